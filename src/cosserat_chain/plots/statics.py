"""Fig. 2 of the paper, done exactly: phi_0 against M from the relaxation protocol and from continuation.

Contract
--------
:func:`figure2` draws two panels from results already computed:

* left, phi_0 of the loaded particle against M: markers at the load steps of the
  relaxation protocol that ended at rest (the paper's circles), a star at each
  model's onset of rotation (the paper's stars), the continuation branches
  (stable solid, unstable dashed) and the small-load tangent phi_0 = c M;
* right, the full moment-rotation characteristic M(phi_0) over one turn.

It never computes anything itself.
"""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from ..experiments.critical import CriticalResult
from ..experiments.sweep import SweepResult
from ..models import available_models, get_model

#: The colours and legend labels of the paper's three models, the same in every figure.
#: Any other model gets :func:`model_color` and :func:`model_label`'s fallbacks.
MODEL_COLORS = {"nonlinear": "tab:blue", "sine": "tab:orange", "linear": "tab:green"}
MODEL_LABELS = {"nonlinear": "nonlinear (1)", "sine": "sine-Cosserat (2)", "linear": "linear Cosserat (3)"}


def model_color(name: str) -> str:
    """The model's colour, the same in every figure.

    The paper's models have theirs (:data:`MODEL_COLORS`); the other registered
    models take the next colours of matplotlib's cycle in registration order, and
    an unregistered name (a file from elsewhere) the one after them.
    """
    if name in MODEL_COLORS:
        return MODEL_COLORS[name]
    others = [other for other in available_models() if other not in MODEL_COLORS]
    index = len(MODEL_COLORS) + (others.index(name) if name in others else len(others))
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return cycle[index % len(cycle)]


def model_label(name: str) -> str:
    """Legend label: the paper's wording (:data:`MODEL_LABELS`), else the model's name and equation."""
    if name in MODEL_LABELS:
        return MODEL_LABELS[name]
    try:
        model = get_model(name)
    except ValueError:
        return name
    return f"{model.name}, {model.equation}"


def _runs(flags: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Split index ranges where ``flags`` is constant; each run shares its end point with the next."""
    edges = np.flatnonzero(np.diff(flags.astype(int))) + 1
    bounds = [0, *edges.tolist(), len(flags)]
    return [(np.arange(lo, min(hi + 1, len(flags))), bool(flags[lo])) for lo, hi in zip(bounds[:-1], bounds[1:])]


#: The moment axis of every statics figure: M in units of E1 h^2, the paper's dimensionless moment.
MOMENT_LABEL = r"moment $M / (E_1 h^2)$"


def _branch_lines(ax, moment, phi0, stable, color, label, swap=False):
    for k, (idx, is_stable) in enumerate(_runs(stable)):
        xs, ys = (phi0[idx], moment[idx]) if swap else (moment[idx], phi0[idx])
        ax.plot(xs, ys, color=color, linestyle="-" if is_stable else "--", label=label if k == 0 else None)


def figure2(
    criticals: Mapping[str, CriticalResult],
    sweeps: Mapping[str, SweepResult] | None = None,
    *,
    figsize: tuple[float, float] = (11.0, 4.5),
) -> Figure:
    """The paper's Fig. 2 (left) and the characteristic M(phi_0) over one turn (right).

    Parameters
    ----------
    criticals : mapping model name -> CriticalResult
        Branches, folds and compliances (:func:`~cosserat_chain.experiments.critical.critical_point`).
    sweeps : mapping model name -> SweepResult, optional
        Relaxation protocols (:func:`~cosserat_chain.experiments.sweep.relaxation_sweep`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    sweeps = sweeps or {}
    # Moments in units of E1 h^2 (the paper's "dimensionless moment"): chains of other h or E1 compare on one axis.
    scale = next(iter([*criticals.values(), *sweeps.values()])).params.moment_scale if (criticals or sweeps) else 1.0
    fig, (left, right) = plt.subplots(1, 2, figsize=figsize, constrained_layout=True)
    m_top = max([0.0, *(abs(r.critical_moment or 0.0) for r in criticals.values()), *(np.max(np.abs(s.moment)) for s in sweeps.values())])
    m_top = 1.15 * (m_top or 0.3) / scale
    compliance = None
    for name, result in criticals.items():
        color = model_color(name)
        branch = result.branch
        ahead = np.maximum.accumulate(np.abs(branch.phi0)) <= np.pi  # first half turn: the branch of Fig. 2
        _branch_lines(left, branch.moment[ahead] / scale, branch.phi0[ahead], branch.stable[ahead], color, model_label(name))
        _branch_lines(right, branch.moment / scale, branch.phi0, branch.stable, color, model_label(name), swap=True)
        for fold in branch.folds:
            if abs(fold.phi0) <= np.pi:
                left.plot(fold.moment / scale, fold.phi0, "o", mfc="white", mec=color, ms=7)
            right.plot(fold.phi0, fold.moment / scale, "o", mfc="white", mec=color, ms=7)
        compliance = result.compliance
    for name, sweep in sweeps.items():
        color = model_color(name)
        up = (sweep.direction == "up") & (sweep.status == "static")
        left.plot(sweep.moment[up] / scale, sweep.phi0[up], "o", color=color, ms=4, alpha=0.8)
        if sweep.onset_load is not None:
            before = sweep.phi0[up][-1] if up.any() else 0.0
            left.plot(sweep.onset_load / scale, before, "*", color=color, ms=15, mec="k", mew=0.6)
    if compliance is not None:
        moments = np.array([0.0, m_top])
        left.plot(moments, compliance * scale * moments, ":", color="0.4", label=f"tangent $\\varphi_0 = c M$, c = {compliance:.4g}")
    left.set(xlim=(0, m_top), ylim=(0, np.pi), xlabel=MOMENT_LABEL, ylabel=r"$\varphi_0$ of the loaded particle (rad)")
    left.set_title("Fig. 2: circles relaxation, stars onset, lines continuation", fontsize=10)
    left.legend(fontsize=8, loc="upper left")
    right.axhline(0.0, color="0.7", lw=0.8)
    folds = [abs(r.critical_moment) / scale for r in criticals.values() if r.critical_moment is not None]
    if folds:
        right.set_ylim(-1.4 * max(folds), 1.4 * max(folds))  # the linear model's line would flatten the folds
    right.set(xlim=(0, 2 * np.pi), xlabel=r"$\varphi_0$ (rad)", ylabel=r"$M / (E_1 h^2)$ holding the particle")
    right.set_xticks(np.pi * np.arange(5) / 2, ["0", r"$\pi/2$", r"$\pi$", r"$3\pi/2$", r"$2\pi$"])
    right.set_title("characteristic over one turn (dashed: unstable, open circles: folds)", fontsize=10)
    return fig


def hysteresis_figure(
    sweeps: Mapping[str, SweepResult],
    criticals: Mapping[str, CriticalResult] | None = None,
    *,
    figsize: tuple[float, float] = (6.5, 4.5),
) -> Figure:
    """The hysteresis loop: mean angular velocity of the loaded particle at each load step, up and down.

    Filled markers: the upward sweep; open markers: the downward one; a dotted vertical
    line at each model's exact static fold M_c.
    """
    criticals = criticals or {}
    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    for name, sweep in sweeps.items():
        color = model_color(name)
        scale = sweep.params.moment_scale
        rate = sweep.angular_velocity[:, sweep.params.N + sweep.particle]
        for direction, style in (("up", {"mfc": color}), ("down", {"mfc": "white"})):
            sel = sweep.direction == direction
            ax.plot(
                sweep.moment[sel] / scale,
                rate[sel],
                "o-" if direction == "up" else "s--",
                color=color,
                ms=5,
                mec=color,
                label=f"{model_label(name)}, load {direction}",
                **style,
            )
        if name in criticals and criticals[name].critical_moment is not None:
            ax.axvline(criticals[name].critical_moment / scale, color=color, ls=":", lw=1)
    ax.set(xlabel=MOMENT_LABEL, ylabel="mean angular velocity of the loaded particle")
    ax.set_title("hysteresis of the onset of rotation (dotted: exact fold $M_c$)", fontsize=10)
    ax.legend(fontsize=8)
    return fig


def critical_against_length(results: dict[str, list]):
    """M_c and phi_0 at the fold against N (one :class:`~cosserat_chain.experiments.critical.CriticalResult` per N and model).

    The sine model's M_c falls like 1/N (it is 1/(largest rotation compliance)), so
    its panel shows N M_c; the nonlinear model's M_c falls slowly.
    """
    import matplotlib.pyplot as plt

    fig, (ax_moment, ax_angle) = plt.subplots(1, 2, figsize=(9, 3.6))
    for name, rows in results.items():
        rows = [r for r in rows if r.fold is not None]
        n = np.array([r.params.N for r in rows])
        moment = np.array([r.critical_moment / r.params.moment_scale for r in rows])
        scaled = name == "sine"
        ax_moment.semilogx(
            n,
            moment * n if scaled else moment,
            "o-",
            color=model_color(name),
            label=f"{model_label(name)}" + (": N M_c" if scaled else ": M_c"),
        )
        ax_angle.semilogx(n, [r.phi0_at_fold for r in rows], "o-", color=model_color(name), label=model_label(name))
    ax_moment.set_xlabel("N (2N+1 particles)")
    ax_moment.set_ylabel(r"critical moment $M_c / (E_1 h^2)$")
    ax_moment.legend(fontsize=8)
    ax_angle.set_xlabel("N (2N+1 particles)")
    ax_angle.set_ylabel("phi_0 at the fold (rad)")
    fig.tight_layout()
    return fig
