"""The relaxation protocol for a batch of chains at once (lock-step sweeps on the compiled batch loop).

Contract
--------
:func:`relaxation_sweeps` runs :func:`~cosserat_chain.experiments.sweep.relaxation_sweep`
for every member of a batch of parameter sets (same N, same model): each member
follows its own sequential sweep (loads raised step by step, each step from
that member's previous end state, optionally back down), and the members' steps
are advanced together by :func:`~cosserat_chain.numerics.batch.run_plans`, one
compiled call per chunk for the whole batch. A member whose step ends starts
its next load at once, and a member whose sweep is over leaves the batch.

The relaxation steps are those of :func:`~cosserat_chain.numerics.relaxation.relax`
(same chunks, time steps and tests), so every member's :class:`SweepResult`
equals ``relaxation_sweep``'s for the same inputs: the same statuses, onset and
stop loads, times and turns, and the same end states to the last bit.

Ctrl-C ends all sweeps; the steps each member finished are returned
(``completed`` False for the members that had not finished), never lost.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np

from ..loads import moment_load
from ..models.base import Model, get_model
from ..numerics.batch import Plan, run_plans
from ..params import ChainParams
from .sweep import NOT_CONVERGED, ROTATING, SweepResult, load_steps, sweep_result

log = logging.getLogger(__name__)


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

    Parameters
    ----------
    params_list : sequence of ChainParams (B)
        The members; all with the same N.
    model : str or Model
    m_max : float or sequence of float (B)
        Largest moment, the same for all or one per member.
    steps, dm : int or float
        Number of load steps or load increment (exactly one), see
        :func:`~cosserat_chain.experiments.sweep.load_steps`.
    down, stop_at_onset, particle
        As in :func:`~cosserat_chain.experiments.sweep.relaxation_sweep`.
    threads : int
        Split the members over this many cores.
    progress : callable(steps_done, steps_total), optional
        Load steps finished over all members, and their largest total.
    **relax_options
        ``t_max``, ``v_tol``, ``f_tol``, ``chunk_time``, ``window_turns``,
        ``omega_rtol``, ``dt`` (a number or one per member) and ``method``, as in
        :func:`~cosserat_chain.numerics.batch.relax_batch`.

    Returns
    -------
    list of SweepResult (B)
        Member by member what ``relaxation_sweep`` returns.

    Raises
    ------
    ValueError
        For bad input, naming the member and the field (see :func:`~cosserat_chain.numerics.batch.relax_batch`).
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
        log.warning("relaxation sweeps interrupted; %d finished steps kept", done[0])
    results = []
    for i, params in enumerate(params_list):
        options = dict(relax_options)
        if np.ndim(options.get("dt")) == 1:
            options["dt"] = float(options["dt"][i])
        settings = {"m_max": float(tops[i]), "steps": steps, "dm": dm, "down": down, "stop_at_onset": stop_at_onset, **options}
        results.append(sweep_result(params, model.name, particle, records[i], finished[i], settings))
    return results
