"""The paper's relaxation protocol (Section 4, Fig. 2): the load raised step by step, each step run to rest.

Contract
--------
:func:`relaxation_sweep` raises the moment on the loaded particle from 0 to
``m_max`` in equal steps; at each step it runs :func:`~cosserat_chain.numerics.relaxation.relax`
from the previous step's end state and records the end state, its status
(``static``, ``rotating``, ``not_converged``) and, for a rotating state, the mean
angular velocity of every particle. The first rotating step is the *onset load*
(the stars of Fig. 2). With ``down=True`` the load is then lowered again from the
last state, step by step to 0, and the first static step on the way down is the
*stop load*; up and down together trace the hysteresis loop.

Ctrl-C ends the sweep after the step in progress is abandoned; the steps already
finished are returned (``completed`` False), never lost.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ..loads import Loads, moment_load
from ..models.base import Model, get_model
from ..numerics.relaxation import Plan, run_plans
from ..params import ChainParams
from ..state import ROW_INDEX, ROWS, column
from ..status import Status
from .simulation import run_attributes

if TYPE_CHECKING:  # xarray is imported where a Dataset is built or read: commands without file output start without it
    import xarray as xr

log = logging.getLogger(__name__)

#: Statuses of a load step.
STATIC, ROTATING, NOT_CONVERGED = Status.STATIC, Status.ROTATING, Status.NOT_CONVERGED


def load_steps(m_max: float, *, steps: int | None = None, dm: float | None = None) -> np.ndarray:
    """The loads dm, 2 dm, ..., m_max of the upward sweep (exactly one of ``steps`` and ``dm``).

    With ``dm`` the last load is the largest multiple of dm not above m_max (to round-off).

    Raises
    ------
    ValueError
        If m_max is not finite, both or neither of steps and dm are given, or either is not positive.
    """
    if not math.isfinite(m_max) or m_max == 0:
        raise ValueError(f"m_max must be a finite non-zero moment, got {m_max!r}")
    if (steps is None) == (dm is None):
        raise ValueError("give exactly one of steps (the number of load steps) and dm (the load increment)")
    if steps is not None:
        if not (isinstance(steps, int) and steps >= 1):
            raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
        return _tidy(m_max * np.arange(1, steps + 1) / steps)
    if not (math.isfinite(dm) and dm > 0):
        raise ValueError(f"dm must be a finite number > 0, got {dm!r}")
    count = int(math.floor(abs(m_max) / dm * (1 + 1e-12)))
    if count < 1:
        raise ValueError(f"dm={dm!r} is larger than |m_max|={abs(m_max)!r}: no load step")
    return _tidy(math.copysign(dm, m_max) * np.arange(1, count + 1))


def _tidy(loads: np.ndarray) -> np.ndarray:
    """Round to 14 significant digits, so that 8 x 0.025 prints as 0.2 (the loads are set values, not results)."""
    return np.array([float(f"{m:.14g}") for m in loads])


@dataclass
class SweepResult:
    """The recorded steps of a relaxation sweep.

    Attributes
    ----------
    moment : ndarray (k,)
        Load of each step, in the order run (up, then down).
    direction : ndarray of str (k,)
        ``up`` or ``down``.
    status : ndarray of str (k,)
    x : ndarray (k, 3, 2N+1)
        End state of each step.
    angular_velocity : ndarray (k, 2N+1)
        Mean d phi / dt of every particle (0 when static, NaN when not converged).
    time : ndarray (k,)
        Time each step took to reach its status.
    turns : ndarray (k,)
        Turns of the loaded particle during each step.
    onset_load, stop_load : float or None
        First rotating load going up; first static load going down after rotating.
    completed : bool
        False if the sweep was interrupted; the steps finished are kept.
    """

    params: ChainParams
    model: str
    particle: int
    moment: np.ndarray
    direction: np.ndarray
    status: np.ndarray
    x: np.ndarray
    angular_velocity: np.ndarray
    time: np.ndarray
    turns: np.ndarray
    onset_load: float | None
    stop_load: float | None
    completed: bool
    settings: dict = field(default_factory=dict)
    #: Constant loads that acted throughout besides the stepped moment (``loads=`` of the sweep).
    loads: Loads = field(default_factory=Loads)

    @property
    def phi0(self) -> np.ndarray:
        """Angle of the loaded particle at the end of each step."""
        return self.x[:, ROW_INDEX["phi"], column(self.params, self.particle)]

    def as_dict(self) -> dict:
        """JSON-ready summary: loads, phi0, status per step, onset and stop loads. Moments in the parameters' units; ``moment_scale`` = E1 h^2 divides them into the paper's dimensionless moment (Fig. 2)."""
        return {
            "model": self.model,
            "particle": self.particle,
            "loads": self.moment.tolist(),
            "moment_scale": self.params.moment_scale,
            "direction": self.direction.tolist(),
            "phi0": self.phi0.tolist(),
            "status": self.status.tolist(),
            "mean_angular_velocity": [
                None if not math.isfinite(w) else w for w in self.angular_velocity[:, column(self.params, self.particle)]
            ],
            "onset_load": self.onset_load,
            "stop_load": self.stop_load,
            "completed": self.completed,
            "extra_loads": self.loads.to_list(),
        }

    def to_dataset(self) -> xr.Dataset:
        """Self-describing Dataset with dims ``step`` and ``particle`` (-N..N)."""
        import xarray as xr

        particle = np.arange(-self.params.N, self.params.N + 1)
        data = {row: (("step", "particle"), self.x[:, i, :]) for i, row in enumerate(ROWS)}
        data["angular_velocity"] = (("step", "particle"), self.angular_velocity)
        data["status"] = (("step",), self.status.astype(str))
        data["relax_time"] = (("step",), self.time)
        data["turns"] = (("step",), self.turns)
        data["phi0"] = (("step",), self.phi0)
        data["onset_load"] = ((), np.nan if self.onset_load is None else self.onset_load)
        data["stop_load"] = ((), np.nan if self.stop_load is None else self.stop_load)
        ds = xr.Dataset(data, coords={"step": np.arange(len(self.moment)), "particle": particle})
        ds = ds.assign_coords(moment=("step", self.moment), direction=("step", self.direction.astype(str)))
        ds["onset_load"].attrs["long_name"] = "first load of the upward sweep at which the loaded particle rotates (NaN: none)"
        ds["stop_load"].attrs["long_name"] = "first load of the downward sweep at which rotation has stopped (NaN: none)"
        # loads_json: the loads besides the stepped moment, which the moment coordinate gives.
        ds.attrs.update(run_attributes(self.params, get_model(self.model), self.loads))
        ds.attrs.update(
            {
                "experiment": "relaxation_sweep",
                "loaded_particle": self.particle,
                "completed": int(self.completed),
                "protocol_json": json.dumps(self.settings),
            }
        )
        return ds


def relaxation_sweep(
    params: ChainParams,
    model: str | Model,
    *,
    m_max: float,
    steps: int | None = None,
    dm: float | None = None,
    down: bool = False,
    stop_at_onset: bool = False,
    particle: int = 0,
    progress: Callable[[int, int], None] | None = None,
    **relax_options,
) -> SweepResult:
    """Run the relaxation protocol up to ``m_max`` (and back down with ``down=True``).

    Parameters
    ----------
    params : ChainParams
    model : str or Model
    m_max : float
        Largest moment.
    steps, dm : int or float
        Number of load steps or load increment (exactly one), see :func:`load_steps`.
    down : bool
        Lower the load again from the last state, down to 0.
    stop_at_onset : bool
        End the upward sweep at the first rotating step (when only the onset
        load is wanted); the downward sweep, if asked for, starts there.
    particle : int
        The loaded particle (default the central one).
    progress : callable(steps_done, steps_total), optional
    **relax_options
        Passed to :func:`~cosserat_chain.numerics.relaxation.relax` (``t_max``,
        ``v_tol``, ``f_tol``, ``chunk_time``, ``window_turns``, ``omega_rtol``, ``dt``, ``method``).

    Returns
    -------
    SweepResult
        A sweep of one member of :func:`relaxation_sweeps`.
    """
    return relaxation_sweeps(
        [params], model, m_max=m_max, steps=steps, dm=dm, down=down, stop_at_onset=stop_at_onset, particle=particle,
        progress=progress, **relax_options,
    )[0]  # fmt: skip


def relaxation_sweeps(
    params_list: Sequence[ChainParams],
    model: str | Model,
    *,
    m_max: float | Sequence[float],
    steps: int | None = None,
    dm: float | None = None,
    down: bool = False,
    stop_at_onset: bool = False,
    particle: int = 0,
    threads: int = 1,
    progress: Callable[[int, int], None] | None = None,
    **relax_options,
) -> list[SweepResult]:
    """Run the relaxation protocol for every member of a batch, in lock-step.

    Each member follows its own sequential sweep (loads raised step by step, each
    step from that member's previous end state, optionally back down), and the
    members' steps are advanced together by
    :func:`~cosserat_chain.numerics.relaxation.run_plans`: a member whose step
    ends starts its next load at once, one whose sweep is over leaves the batch.
    Ctrl-C ends all sweeps; the steps each member finished are returned
    (``completed`` False for the members that had not finished), never lost.

    Parameters
    ----------
    params_list : sequence of ChainParams (B)
        The members; all with the same N.
    model : str or Model
    m_max : float or sequence of float (B)
        Largest moment, the same for all or one per member.
    steps, dm, down, stop_at_onset, particle
        As in :func:`relaxation_sweep`.
    threads : int
        Split the members over this many cores.
    progress : callable(steps_done, steps_total), optional
        Load steps finished over all members, and their total.
    **relax_options
        As in :func:`~cosserat_chain.numerics.relaxation.relax`; ``dt`` may give one step per member.

    Returns
    -------
    list of SweepResult (B)

    Raises
    ------
    ValueError
        For bad input, naming the member and the field.
    IntegrationError
        If a member blows up.
    """
    params_list = list(params_list)
    model = get_model(model)
    size = len(params_list)
    tops = np.broadcast_to(np.asarray(m_max, dtype=float), (size,)) if np.ndim(m_max) == 0 else np.asarray(m_max, dtype=float)
    if tops.shape != (size,):
        raise ValueError(f"m_max must be a number or one value per member ({size}), got shape {tops.shape}")
    ups = []
    for i, (params, top) in enumerate(zip(params_list, tops)):
        try:
            ups.append(load_steps(float(top), steps=steps, dm=dm))
            moment_load(float(top), particle).validate(params)
        except ValueError as err:
            raise ValueError(f"member {i} (params_list[{i}]): {err}") from None
    totals = [2 * len(up) if down else len(up) for up in ups]
    records: list[list[tuple[float, str, object]]] = [[] for _ in range(size)]
    finished = [False] * size
    done = [0]

    def plan(i: int) -> Plan:
        def record(moment: float, direction: str, step) -> None:
            if step.status == NOT_CONVERGED:
                log.warning("member %d, load %g: %s", i, moment, step.message)
            records[i].append((moment, direction, step))
            done[0] += 1
            if progress is not None:
                progress(done[0], sum(totals))

        for moment in ups[i]:
            step = yield float(moment)
            record(float(moment), "up", step)
            if stop_at_onset and step.status == ROTATING:
                break
        if down:
            top = len(records[i])
            for moment in np.append(ups[i][: top - 1][::-1], 0.0):
                step = yield float(moment)
                record(float(moment), "down", step)
        finished[i] = True

    try:
        run_plans(params_list, model, [plan(i) for i in range(size)], particle=particle, threads=threads, **relax_options)
    except KeyboardInterrupt:
        log.warning("relaxation sweep interrupted; %d finished steps kept", done[0])
    results = []
    for i, params in enumerate(params_list):
        options = dict(relax_options)
        extra = Loads(options.pop("loads", None) or ())
        if np.ndim(options.get("dt")) == 1:
            options["dt"] = float(options["dt"][i])
        settings = {"m_max": float(tops[i]), "steps": steps, "dm": dm, "down": down, "stop_at_onset": stop_at_onset, **options}
        results.append(replace(sweep_result(params, model.name, particle, records[i], finished[i], settings), loads=extra))
    return results


def sweep_result(params, model_name, particle, records, completed, settings) -> SweepResult:
    """Assemble a :class:`SweepResult` from ``(moment, direction, RelaxationStep)`` records."""
    n = params.n_particles
    status = np.array([r[2].status for r in records], dtype=object)
    direction = np.array([r[1] for r in records], dtype=object)
    moment = np.array([r[0] for r in records], dtype=float)
    onset = next((m for m, d, s in zip(moment, direction, status) if d == "up" and s == ROTATING), None)
    stop = None
    rotating = bool(np.any(direction == "up")) and status[direction == "up"][-1] == ROTATING
    for m, d, s in zip(moment, direction, status):
        if d != "down":
            continue
        if s == ROTATING:
            rotating = True
        elif s == STATIC and rotating:
            stop = float(m)
            break
    return SweepResult(
        params=params,
        model=model_name,
        particle=particle,
        moment=moment,
        direction=direction,
        status=status,
        x=np.array([r[2].x for r in records]).reshape(-1, 3, n),
        angular_velocity=np.array([r[2].angular_velocity for r in records]).reshape(-1, n),
        time=np.array([r[2].time for r in records]),
        turns=np.array([r[2].turns for r in records]),
        onset_load=None if onset is None else float(onset),
        stop_load=stop,
        completed=completed,
        settings=settings,
    )
