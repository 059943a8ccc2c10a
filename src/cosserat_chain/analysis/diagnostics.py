"""Streaming diagnostics of a long run: turns, extreme excursions, energy localization.

Contract
--------
:class:`StreamingDiagnostics` is updated chunk by chunk with the frames of each
chunk (every step of it) and keeps only per-particle summaries, never the
frames, so a run of any length needs constant memory. Feeding one trajectory in
chunks gives the same diagnostics as feeding it whole: maxima, turn counts and
turn times exactly, the run averages to round-off (only the order of a sum
changes). The state round-trips through :meth:`StreamingDiagnostics.to_variables`
and :meth:`StreamingDiagnostics.from_variables` (a checkpoint).

Definitions (theta_k = phi_k - phi_k(t_start), the unwrapped angle: phi is never
wrapped by the integrators):

* winding number: trunc(theta_k / 2 pi), the signed number of full turns made
  (floor for theta_k >= 0; a small swing to negative angles is 0 turns, not -1);
* turns made: the largest |winding number| reached during the run, and the time
  at which it was last increased; for the loaded particle, the turns completed
  along the sense of its moment (``direction``), found and timed by the engine's
  turn detector (:func:`~cosserat_chain.numerics.engine.turns_in_frames`);
* mean angular velocity of the loaded particle: theta / (t - t_start); and over
  the most recent ``WINDOW_TURNS`` full turns, 2 pi k / (time of turn n - time of
  turn n - k), the turn times interpolated linearly between steps;
* energy of a free particle: its kinetic energy plus half the energy of each of
  its two bonds (a bond to a clamped end counts wholly for the free particle).
  Bond energies are the model's :meth:`~cosserat_chain.models.base.Model.bond_energy`:
  exact for the nonlinear model (the four links of eq. 1) and the linear model
  (eq. 3); the sine model (eq. 2) has no potential, so its bonds are given the
  linear model's bond energy evaluated at (u, v, sin phi), whose forces are the
  sine model's in the linearised rotations. For a model without bond energies the
  energy measures below are NaN and everything else is computed;
* participation ratio of the energies e_k of the 2N-1 free particles:
  PR = (sum e_k)^2 / sum e_k^2, between 1 (all energy on one particle) and 2N-1
  (evenly spread), averaged over the steps with non-zero energy;
* a particle is *rotating* if it made at least one full turn and made its latest
  new turn in the last ``RECENT_FRACTION`` of the run;
* the *amplitudes of the others*: the largest |phi| (rad), |u| / h and |v| / h over the
  steps and over the particles other than the loaded one, each against its threshold
  in :data:`THRESHOLDS` (:data:`SMALL_ANGLE`, :data:`SMALL_DISPLACEMENT`): the paper's
  "other particles performed small oscillations only" (end of Section 4) is two claims,
  that no other particle turns and that the others' motion is small;
* the run is ``static`` if no particle rotates, ``several_rotating`` if a particle other
  than the loaded one does, and if exactly the loaded one does, ``localized_rotation``
  when every amplitude of the others is within its threshold and
  ``rotation_with_large_motion`` when one is not (``large_motion`` names them);
* the model's *range of validity*: a model whose forces are linear in u and v (the sine
  model (2) and the linear model (3); found from the model's stiffness, which is then
  independent of u and v, :func:`linear_rows`) describes displacements up to
  :data:`SMALL_DISPLACEMENT` h only, and one linear in phi (the linear model) angles up
  to :data:`SMALL_ANGLE`; ``outside_validity`` names what went beyond, over every particle.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from ..models.base import Model, get_model
from ..numerics.engine import turns_in_frames
from ..params import ChainParams
from ..state import column, zero_held

log = logging.getLogger(__name__)

TWO_PI = 2.0 * math.pi
#: The recent angular velocity is measured over this many of the latest full turns.
WINDOW_TURNS = 10
#: A particle still rotates if its latest new turn lies in this last fraction of the run.
RECENT_FRACTION = 0.25
CLASSIFICATIONS = ("static", "localized_rotation", "rotation_with_large_motion", "several_rotating")
#: Largest ratio of the first neglected (quadratic) term to the kept linear one at which a
#: motion counts as small: the linear models (2)-(3) keep only the linear terms in the
#: displacements (eq. (2)) or in the displacements and angles (eq. (3)).
LINEARISATION_TOLERANCE = 0.1
#: Largest |phi| (rad) of a small rotation: a corner r of a particle turned by phi moves by
#: phi J r - phi^2 r / 2 + O(phi^3), the quadratic term phi / 2 of the linear one, which is
#: LINEARISATION_TOLERANCE at 0.2 rad (sin phi = phi to phi^2 / 6 = 0.7 % there).
SMALL_ANGLE = 2.0 * LINEARISATION_TOLERANCE
#: Largest |u| / h and |v| / h of a small displacement: a link of length l whose ends move
#: apart by Delta (at most twice the particles' largest displacement) changes its length by
#: Delta_parallel + Delta_perp^2 / (2 l) + ..., the quadratic term Delta / (2 l) of the linear
#: one, which is LINEARISATION_TOLERANCE for links about h long at displacements of 0.1 h.
SMALL_DISPLACEMENT = LINEARISATION_TOLERANCE
#: The thresholds of the others' amplitudes, by name: phi in rad, u and v in units of h.
THRESHOLDS = {"phi": SMALL_ANGLE, "u_over_h": SMALL_DISPLACEMENT, "v_over_h": SMALL_DISPLACEMENT}
#: Rows of the state (u, v, phi) named as in THRESHOLDS.
_AMPLITUDE_ROWS = {"u_over_h": 0, "v_over_h": 1, "phi": 2}
#: Size of the probe displacements and angles of linear_rows (a moderate state, not rest).
_PROBE = 0.3
#: Relative change of the stiffness below which linear_rows takes it as unchanged (round-off).
_LINEAR_RTOL = 1e-12


def linear_rows(params: ChainParams, model: str | Model) -> tuple[str, ...]:
    """The rows of the state (``"u_over_h"``, ``"v_over_h"``, ``"phi"``) in which the model's forces are linear.

    A model is linear in a row if its stiffness -dF/dq does not change when that row alone
    is displaced from rest (by a fixed pseudo-random state of size 0.3 h or 0.3 rad): the
    sine model (2) in u and v (its stiffness is K diag(1, 1, cos phi)), the linear model (3)
    in all three, the nonlinear model (1) in none. Computed, so that any registered model
    is judged by its forces, not by its name.
    """
    model = get_model(model)
    rest = model.stiffness(params, np.zeros((3, params.n_particles))).tocsr()
    scale = abs(rest).max()
    probe = _PROBE * np.sin(np.arange(1, params.n_particles + 1) * 1.7)  # deterministic, no symmetry
    rows = []
    for name, row in _AMPLITUDE_ROWS.items():
        x = np.zeros((3, params.n_particles))
        x[row] = probe * (params.h if row < 2 else 1.0)
        zero_held(params, x)  # what the ends hold stays at rest
        change = abs(model.stiffness(params, x).tocsr() - rest).max()
        if change <= _LINEAR_RTOL * scale:
            rows.append(name)
    return tuple(rows)


def bond_energies(params: ChainParams, model: str | Model, x: np.ndarray) -> np.ndarray:
    """Energy stored in every bond, for any number of configurations.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        A registered model; see the module docstring for the sine model's
        (linearised) bond energy.
    x : ndarray (..., 3, 2N+1)

    Returns
    -------
    ndarray (..., n_bonds)
        Bond k joins columns k and k+1 (a ring's closing bond, last, joins 2N and 0).

    Raises
    ------
    NotImplementedError
        For a model without bond energies.
    """
    return get_model(model).bond_energy(params, np.asarray(x, dtype=float))


def particle_energies(params: ChainParams, model: str | Model, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Energy of every particle: kinetic plus its share of the bond energies (module docstring).

    Parameters
    ----------
    x, v : ndarray (..., 3, 2N+1)
        Configurations and velocities.

    Returns
    -------
    ndarray (..., 2N+1)
        Particles -N..N; the sum over them is the total (kinetic + bond) energy. A
        clamped end holds none: its halves of its bond go to its free neighbour.
    """
    bonds = bond_energies(params, model, x)
    inertia = params.particle_inertia
    energy = 0.5 * np.sum(inertia * np.asarray(v, dtype=float) ** 2, axis=-2)
    n = params.n_particles
    energy[..., : bonds.shape[-1]] += 0.5 * bonds
    energy[..., 1:] += 0.5 * bonds[..., : n - 1]
    if params.periodic:
        energy[..., 0] += 0.5 * bonds[..., -1]
    for end, (col, neighbour) in zip(params.ends, ((0, 1), (n - 1, n - 2))):
        if end == "clamped":
            energy[..., neighbour] += energy[..., col]
            energy[..., col] = 0.0
    return energy


def participation_ratio(energy: np.ndarray) -> np.ndarray:
    """(sum e)^2 / sum e^2 over the last axis; NaN where all e are zero."""
    energy = np.asarray(energy, dtype=float)
    squares = np.sum(energy**2, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(squares > 0, np.sum(energy, axis=-1) ** 2 / squares, np.nan)


class StreamingDiagnostics:
    """Per-particle summaries of a run, updated from the frames of one chunk at a time.

    Parameters
    ----------
    params : ChainParams
    model : str or Model
        A registered model.
    particle : int
        The loaded particle, in -N+1..N-1.
    x0, v0 : ndarray (3, 2N+1)
        State at the start of the run (counted as its first frame).
    t0 : float
        Time of the start.
    direction : {1.0, -1.0}
        Sense in which the loaded particle's turns count (the sign of its moment).

    Notes
    -----
    See the module docstring for the definitions. Attributes that are arrays
    run over all 2N+1 particles (clamped ends included, where they stay zero).
    ``has_energy`` is False for a model without bond energies, whose
    participation ratio and energy shares stay NaN.
    """

    #: Names of the array state saved by :meth:`to_variables`, all over ``particle``.
    _PER_PARTICLE = ("angle_start", "angle", "max_abs_u", "max_abs_v", "max_abs_phi", "turns", "last_turn_time", "energy_share_sum")
    _SCALARS = ("t_start", "time", "steps", "participation_sum", "energy_steps")

    def __init__(
        self,
        params: ChainParams,
        model: str | Model,
        particle: int,
        x0: np.ndarray,
        v0: np.ndarray,
        t0: float = 0.0,
        direction: float = 1.0,
    ):
        self.params = params
        self.direction = float(direction)
        self.model = get_model(model)
        self.particle = particle
        self.column = column(params, particle)
        x0 = np.asarray(x0, dtype=float)
        n = params.n_particles
        self.t_start = float(t0)
        self.time = float(t0)
        self.steps = 0
        self.angle_start = x0[2].copy()
        self.angle = x0[2].copy()
        self.max_abs_u = np.abs(x0[0])
        self.max_abs_v = np.abs(x0[1])
        self.max_abs_phi = np.abs(x0[2])
        self.turns = np.zeros(n, dtype=np.int64)
        self.last_turn_time = np.full(n, np.nan)
        #: Interpolated times of the loaded particle's latest (up to WINDOW_TURNS + 1) full turns.
        self.turn_times = np.zeros(0)
        self.participation_sum = 0.0
        self.energy_share_sum = np.zeros(n)
        self.energy_steps = 0
        self.has_energy = True
        try:
            self._accumulate_energy(np.asarray(x0, dtype=float)[None], np.asarray(v0, dtype=float)[None])
        except NotImplementedError as err:
            # Turns, excursions and the classification do not need energies: keep them.
            log.info("%s; the energy localization measures are NaN", err)
            self.has_energy = False

    # ------------------------------------------------------------------ updating
    def update(self, time: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        """Take in the frames of one chunk.

        Parameters
        ----------
        time : ndarray (F,)
        x, v : ndarray (F, 3, 2N+1)
            Consecutive steps; frame 0 is the state already taken in (the end of
            the previous chunk, or the start), so only frames 1..F-1 are new.
        """
        time = np.asarray(time, dtype=float)
        x = np.asarray(x, dtype=float)
        if time.size < 2:
            return
        new = x[1:]
        self.max_abs_u = np.maximum(self.max_abs_u, np.abs(new[:, 0]).max(axis=0))
        self.max_abs_v = np.maximum(self.max_abs_v, np.abs(new[:, 1]).max(axis=0))
        self.max_abs_phi = np.maximum(self.max_abs_phi, np.abs(new[:, 2]).max(axis=0))

        theta = np.abs(x[:, 2] - self.angle_start)
        levels = np.floor(theta / TWO_PI).astype(np.int64)
        running = np.maximum.accumulate(np.concatenate([self.turns[None], levels[1:]]), axis=0)
        increased = running[1:] > running[:-1]
        turned = increased.any(axis=0)
        last = increased.shape[0] - 1 - np.argmax(increased[::-1], axis=0)
        self.last_turn_time = np.where(turned, time[1:][last], self.last_turn_time)

        # The loaded particle's turn times by the engine's detector, along the sense it turns.
        c = self.column
        made, new_times = turns_in_frames(time, x[:, 2, c], self.direction, self.angle_start[c], int(self.turns[c]))
        self.turn_times = np.concatenate([self.turn_times, new_times])[-(WINDOW_TURNS + 1) :]
        self.turns = running[-1].copy()
        self.turns[c] = made

        if self.has_energy:
            self._accumulate_energy(new, np.asarray(v, dtype=float)[1:])
        self.steps += time.size - 1
        self.time = float(time[-1])
        self.angle = x[-1, 2].copy()

    def _accumulate_energy(self, x: np.ndarray, v: np.ndarray) -> None:
        energy = particle_energies(self.params, self.model, x, v)
        total = energy.sum(axis=-1)
        moving = total > 0
        if not moving.any():
            return
        energy, total = energy[moving], total[moving]
        self.participation_sum += float(np.sum(total**2 / np.sum(energy**2, axis=-1)))
        self.energy_share_sum += np.sum(energy / total[:, None], axis=0)
        self.energy_steps += int(moving.sum())

    # ------------------------------------------------------------------ results
    @property
    def unwrapped_angle(self) -> np.ndarray:
        """theta_k = phi_k - phi_k(t_start) at the latest frame, (2N+1,)."""
        return self.angle - self.angle_start

    @property
    def winding(self) -> np.ndarray:
        """Signed full turns trunc(theta_k / 2 pi) at the latest frame, (2N+1,) int."""
        return np.trunc(self.unwrapped_angle / TWO_PI).astype(np.int64)

    @property
    def turns_completed(self) -> int:
        """Full turns made by the loaded particle."""
        return int(self.turns[self.column])

    @property
    def mean_angular_velocity(self) -> float:
        """theta / (t - t_start) of the loaded particle; NaN before the first step."""
        elapsed = self.time - self.t_start
        return float(self.unwrapped_angle[self.column] / elapsed) if elapsed > 0 else math.nan

    @property
    def recent_angular_velocity(self) -> float:
        """Mean angular velocity over the latest (up to ``WINDOW_TURNS``) full turns; NaN before two turns."""
        if self.turn_times.size < 2:
            return math.nan
        sign = 1.0 if self.unwrapped_angle[self.column] >= 0 else -1.0
        return float(sign * TWO_PI * (self.turn_times.size - 1) / (self.turn_times[-1] - self.turn_times[0]))

    @property
    def participation_ratio(self) -> float:
        """Participation ratio of the particle energies averaged over the steps; NaN if nothing moved."""
        return self.participation_sum / self.energy_steps if self.energy_steps else math.nan

    @property
    def mean_energy_share(self) -> np.ndarray:
        """Average fraction of the chain's energy on every particle, (2N+1,) (clamped ends 0)."""
        return self.energy_share_sum / self.energy_steps if self.energy_steps else np.full(self.params.n_particles, np.nan)

    @property
    def rotating(self) -> np.ndarray:
        """Which particles still rotate (module docstring), (2N+1,) bool."""
        recent = self.time - RECENT_FRACTION * (self.time - self.t_start)
        with np.errstate(invalid="ignore"):
            return (self.turns >= 1) & (self.last_turn_time >= recent)

    @property
    def amplitudes_of_others(self) -> dict[str, float]:
        """Largest |phi| (rad), |u| / h and |v| / h over the steps and the particles other than the loaded one."""
        h = self.params.h
        return {
            "phi": self.max_over_others(self.max_abs_phi),
            "u_over_h": self.max_over_others(self.max_abs_u) / h,
            "v_over_h": self.max_over_others(self.max_abs_v) / h,
        }

    @property
    def large_motion(self) -> tuple[str, ...]:
        """The amplitudes of the others beyond their :data:`THRESHOLDS` (names as there)."""
        return tuple(name for name, value in self.amplitudes_of_others.items() if value > THRESHOLDS[name])

    @property
    def outside_validity(self) -> tuple[str, ...]:
        """The rows in which the model is linear (:func:`linear_rows`) whose largest amplitude over every
        particle went beyond its threshold: where the model left its own range of validity."""
        h = self.params.h
        largest = {"phi": float(np.max(self.max_abs_phi)), "u_over_h": float(np.max(self.max_abs_u)) / h,
                   "v_over_h": float(np.max(self.max_abs_v)) / h}  # fmt: skip
        return tuple(name for name in linear_rows(self.params, self.model) if largest[name] > THRESHOLDS[name])

    @property
    def classification(self) -> str:
        """``static``, ``localized_rotation``, ``rotation_with_large_motion`` or ``several_rotating`` (module docstring)."""
        rotating = self.rotating
        others = np.delete(rotating, self.column)
        if others.any():
            return "several_rotating"
        if not rotating[self.column]:
            return "static"
        return "rotation_with_large_motion" if self.large_motion else "localized_rotation"

    def max_over_others(self, values: np.ndarray) -> float:
        """Largest entry of a per-particle array over the particles other than the loaded one."""
        return float(np.max(np.delete(values, self.column)))

    # ------------------------------------------------------------------ checkpoint
    def to_variables(self) -> dict[str, Any]:
        """The state as xarray-ready variables: name -> (dims, values); exact round trip."""
        out: dict[str, Any] = {f"diag_{name}": (("particle",), getattr(self, name)) for name in self._PER_PARTICLE}
        out["diag_turn_times"] = (("recent_turn",), self.turn_times)
        for name in self._SCALARS:
            out[f"diag_{name}"] = ((), getattr(self, name))
        return out

    @classmethod
    def from_variables(
        cls, params: ChainParams, model: str | Model, particle: int, variables: Any, direction: float = 1.0
    ) -> StreamingDiagnostics:
        """Rebuild the accumulator from :meth:`to_variables` (or a Dataset holding them)."""
        n = params.n_particles
        zero = np.zeros((3, n))
        diagnostics = cls(params, model, particle, zero, zero, direction=direction)

        def value(name: str) -> np.ndarray:
            item = variables[f"diag_{name}"]
            return np.asarray(item[1] if isinstance(item, tuple) else item.values)

        for name in cls._PER_PARTICLE:
            array = value(name)
            if array.shape != (n,):
                raise ValueError(f"diag_{name} must have shape ({n},) for N={params.N}, got {array.shape}")
            setattr(diagnostics, name, array.astype(np.int64 if name == "turns" else float))
        diagnostics.turn_times = value("turn_times").astype(float)
        for name in cls._SCALARS:
            scalar = value(name).item()
            setattr(diagnostics, name, int(scalar) if name in ("steps", "energy_steps") else float(scalar))
        return diagnostics
