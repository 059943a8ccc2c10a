"""Minimum energy paths and first-order saddles: the climbing-image string method and P-RFO Newton steps.

Contract
--------
:func:`string_method` relaxes a path of images between two minima of an energy E(x), x in R^n,
onto a minimum energy path (MEP: the gradient along it is tangent to it) by the simplified
string method of E, Ren and Vanden-Eijnden (J. Chem. Phys. 126, 164103, 2007): each iteration
moves every inner image one explicit steepest-descent step, x <- x - dt grad E(x), and then
redistributes the images at equal arc length along the polygon through them, which removes
the gradient's tangential part. The force left on the path is how far an iteration moves its
images, per unit time step: the gradient across the path (the part along it the redistribution
takes back; at a fixed point of the iteration it vanishes, whereas a tangent estimated from the
images would leave an error of the order of their spacing). Once that force has fallen to
:data:`CLIMB_AFTER` of its first value, the highest image climbs (Ren and Vanden-Eijnden, J. Chem. Phys.
138, 134105, 2013; the climbing image of Henkelman, Uberuaga and Jonsson, J. Chem. Phys. 113,
9901, 2000): it moves with -grad E + 2 (grad E . t) t, up along the path's tangent t and down
across it, and the images on each side of it are redistributed separately, so it converges to
the saddle at the path's top and the others to the MEP on each side. The path has converged when
the force left (on the climbing image its whole climbing force) is below ``tolerance``.

:func:`saddle_search` refines a point near a first-order saddle (the climbing image) by Newton
steps with partitioned rational-function shifts (P-RFO; Baker, J. Comput. Chem. 7, 385, 1986):
up along the Hessian's lowest mode, down along the others, a Newton step (quadratic convergence)
as the gradient vanishes.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: The highest image starts climbing once the force left on the path has fallen to this fraction of its first value.
CLIMB_AFTER = 0.1


@dataclass(frozen=True)
class MinimumEnergyPath:
    """A relaxed string of images between two minima.

    Attributes
    ----------
    images : ndarray, shape (M, n)
        The images, the two ends included (images[0] and images[-1] are the given minima).
    energies : ndarray, shape (M,)
        E at each image.
    climbing : int
        The index of the climbing image (the path's top); -1 if none climbed.
    force : float
        The force left: the largest move of an image in the last iteration over the time step.
    iterations : int
        Steps taken.
    converged : bool
        Whether ``force`` fell below the tolerance.
    """

    images: np.ndarray
    energies: np.ndarray
    climbing: int
    force: float
    iterations: int
    converged: bool

    @property
    def top(self) -> int:
        """The index of the highest image."""
        return int(np.argmax(self.energies))

    def maxima(self) -> list[int]:
        """Indices of the inner images higher than both neighbours (the path's local tops), highest first."""
        e = self.energies
        inner = [i for i in range(1, e.size - 1) if e[i] >= e[i - 1] and e[i] >= e[i + 1]]
        return sorted(inner, key=lambda i: -e[i])


def _redistribute(images: np.ndarray, count: int) -> np.ndarray:
    """``count`` images at equal arc length along the polygon through ``images`` (M, n), its ends kept.

    Linear, not a spline: a spline through a poor first path (a jump between two valleys)
    overshoots into states far from both, and the climbing image's saddle is refined anyway.
    """
    lengths = np.linalg.norm(np.diff(images, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    if s[-1] == 0.0:
        return np.repeat(images[:1], count, axis=0)
    targets = np.linspace(0.0, s[-1], count)
    segment = np.clip(np.searchsorted(s, targets, side="right") - 1, 0, images.shape[0] - 2)
    width = np.where(lengths[segment] > 0, lengths[segment], 1.0)
    fraction = np.clip((targets - s[segment]) / width, 0.0, 1.0)
    out = images[segment] + fraction[:, None] * (images[segment + 1] - images[segment])
    out[0], out[-1] = images[0], images[-1]
    return out


def _tangent(images: np.ndarray, energies: np.ndarray, i: int) -> np.ndarray:
    """The unit tangent at image i by the upwind rule of Henkelman and Jonsson (J. Chem. Phys. 113, 9978, 2000) at a top: the mean of both sides."""
    forward, backward = images[i + 1] - images[i], images[i] - images[i - 1]
    forward = forward / max(np.linalg.norm(forward), np.finfo(float).tiny)
    backward = backward / max(np.linalg.norm(backward), np.finfo(float).tiny)
    if energies[i + 1] > energies[i] > energies[i - 1]:
        t = forward
    elif energies[i + 1] < energies[i] < energies[i - 1]:
        t = backward
    else:
        t = forward + backward
    return t / max(np.linalg.norm(t), np.finfo(float).tiny)


def string_method(
    energy_gradient: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    path: np.ndarray,
    *,
    step: float,
    images: int | None = None,
    climb: bool = True,
    tolerance: float = 1e-6,
    max_iterations: int = 100_000,
) -> MinimumEnergyPath:
    """Relax ``path`` onto a minimum energy path by the simplified string method with a climbing image (module docstring).

    Parameters
    ----------
    energy_gradient : callable
        ``energy_gradient(x)`` with x of shape (M, n) returns the energies (M,) and gradients (M, n).
    path : ndarray, shape (K, n)
        The initial path, from the first minimum to the second (K >= 2); redistributed onto
        ``images`` images at equal arc length before the first step.
    step : float
        The steepest-descent time step dt: below 2 / (the Hessian's largest eigenvalue along the path).
    images : int, optional
        Images of the string, the ends included (>= 3); K if omitted.
    climb : bool
        Whether the highest image climbs to the saddle.
    tolerance : float
        The largest force left on the path at convergence (units of grad E).
    max_iterations : int
        Steps before it gives up (``converged`` False).

    Raises
    ------
    ValueError
        For fewer than 3 images, a path of other than two dimensions or a step that is not positive.
    """
    path = np.asarray(path, dtype=float)
    if path.ndim != 2 or path.shape[0] < 2:
        raise ValueError(f"path must be an array (K >= 2 images, n), got shape {path.shape}")
    count = path.shape[0] if images is None else int(images)
    if count < 3:
        raise ValueError(f"images must be >= 3 (the two ends and one inner image), got {count}")
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step!r}")
    x = _redistribute(path, count)
    energies, gradients = energy_gradient(x)
    climbing, start, force = -1, math.inf, math.inf
    for iteration in range(1, max_iterations + 1):
        moved = x - step * gradients
        moved[[0, -1]] = x[[0, -1]]
        if climbing >= 0:
            t = _tangent(x, energies, climbing)
            g = gradients[climbing]
            moved[climbing] = x[climbing] - step * (g - 2 * (g @ t) * t)
            left = _redistribute(moved[: climbing + 1], climbing + 1)
            right = _redistribute(moved[climbing:], count - climbing)
            moved = np.concatenate([left, right[1:]])
        else:
            moved = _redistribute(moved, count)
        # What the step moved an image across the path (along it, redistribution takes it back): the force left.
        force = float(np.max(np.linalg.norm(moved - x, axis=1))) / step
        x = moved
        energies, gradients = energy_gradient(x)
        if force <= tolerance and (climbing >= 0 or not climb):
            return MinimumEnergyPath(x, energies, climbing, force, iteration, True)
        if climb and climbing < 0:
            start = force if math.isinf(start) else start
            if force <= max(CLIMB_AFTER * start, tolerance):
                climbing = int(np.argmax(energies[1:-1])) + 1
    return MinimumEnergyPath(x, energies, climbing, force, max_iterations, False)


@dataclass(frozen=True)
class Saddle:
    """The end of a P-RFO saddle search.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The last iterate.
    gradient : float
        The largest |dE/dx_k| there.
    negative : int
        The Hessian's eigenvalues there below -1e-9 of its scale (1 at a first-order saddle).
    converged : bool
        Whether the gradient fell to ``tolerance`` times the Hessian's largest entry.
    """

    x: np.ndarray
    gradient: float
    negative: int
    converged: bool


def saddle_search(
    gradient_hessian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x: np.ndarray,
    *,
    tolerance: float,
    steps: int = 200,
    trust: float = 0.3,
    eigh: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] = np.linalg.eigh,
) -> Saddle:
    """A first-order saddle from ``x`` by P-RFO Newton steps, each at most ``trust`` long (module docstring).

    Parameters
    ----------
    gradient_hessian : callable
        ``gradient_hessian(x)`` returns grad E (n,) and the Hessian (n, n).
    x : ndarray, shape (n,)
        The start (near the saddle: the climbing image).
    tolerance : float
        Converged where max |grad E| <= tolerance * max |Hessian entry|.
    steps : int
        Newton steps before it gives up.
    trust : float
        The longest step.
    eigh : callable
        The symmetric eigensolver (eigenvalues ascending, vectors as columns).
    """
    x = np.array(x, dtype=float)
    for _ in range(steps):
        gradient, hessian = gradient_hessian(x)
        values, vectors = eigh(hessian)
        scale = max(float(np.max(np.abs(hessian))), np.finfo(float).tiny)
        negative = int(np.sum(values < -1e-9 * scale))
        if np.max(np.abs(gradient)) <= tolerance * scale:
            return Saddle(x, float(np.max(np.abs(gradient))), negative, True)
        g = vectors.T @ gradient
        up = values[0] / 2 + math.sqrt(values[0] ** 2 / 4 + g[0] ** 2)
        augmented = np.diag(np.append(values[1:], 0.0))
        augmented[-1, :-1] = augmented[:-1, -1] = g[1:]
        down = float(np.linalg.eigvalsh(augmented)[0])
        shifted = values[1:] - down
        step = np.concatenate(
            [
                [-g[0] / (values[0] - up) if values[0] != up else 0.0],
                np.divide(-g[1:], shifted, out=np.zeros_like(shifted), where=shifted > 0),
            ]
        )
        step = vectors @ step
        length = float(np.linalg.norm(step))
        if length > trust:
            step *= trust / length
        x = x + step
    gradient, hessian = gradient_hessian(x)
    values = eigh(hessian)[0]
    return Saddle(x, float(np.max(np.abs(gradient))), int(np.sum(values < -1e-9 * np.max(np.abs(values)))), False)
