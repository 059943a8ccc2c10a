"""``cosserat-chain simulate``: one damped simulation under a moment load."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from ..status import Status
from .common import (
    LARGER_STEP,
    MAX_TURN_PER_STEP,
    MethodName,
    app,
    bar_callback,
    checkpoint_or_exit,
    config_or_exit,
    exit_on,
    fail,
    finite_or_none,
    model_option,
    number,
    outputs_or_exit,
    progress_bar,
    save_dataset,
    step_for_checks,
    whole,
    work_or_exit,
)
from .systems import chain_only_or_exit, set_option, simulate_on_system, start_option, system_only_or_exit, system_option, velocity_option


@app.command()
def simulate(
    ctx: typer.Context,
    model: str = model_option("nonlinear", "Model."),
    moment: float | None = number(
        None, "Moment M on the loaded particle (default 0.1 unless the config's [[loads]] or --load give the loads)."
    ),
    t_end: float = number(300.0, "Final time (on the run's time axis with --x0).", above=0.0, flags=("--t-end",)),
    dt: float | None = number(None, "Time step (default 0.1 / highest linear frequency).", above=0.0),
    particle: int = typer.Option(0, help="Loaded particle, in -N+1..N-1 (default the central one)."),
    ramp: float = number(0.0, "Raise the moment linearly over this time (0: applied at once).", at_least=0.0),
    method: MethodName = typer.Option(MethodName.verlet, help="verlet (order 2) or yoshida4 (order 4)."),
    frames: int = whole(201, at_least=2, help="Number of stored states (>= 2: the start and the end)."),
    threads: int = whole(1, at_least=1, help="Threads per step (worth it from ~10^4 particles)."),
    reference: bool = typer.Option(False, help="Use the adaptive DOP853 reference instead of the fixed step."),
    load: list[str] | None = typer.Option(
        None, "--load", help="A constant load ROW:PARTICLE=VALUE (ROW u, v or phi; e.g. v:-2=0.01); repeatable."
    ),
    config: Path | None = typer.Option(
        None,
        help="TOML file with ChainParams fields (E1, E2, h, a, b, m, j, gamma_u, gamma_v, gamma_phi, N, left_end, right_end, "
        "periodic) and [[loads]] tables (row, particle, value or kind: step, ramp, staircase, harmonic, knots); with --system, "
        "the system's [system] table.",
    ),
    x0: Path | None = typer.Option(
        None, "--x0", help="Start from a stored frame of this run (simulate --out): its chain, positions, velocities, time and loads."
    ),
    at: float | None = number(None, "With --x0: the stored frame nearest this time (default the last)."),
    out: Path | None = typer.Option(None, help="Write the trajectory to this NetCDF file."),
    checkpoint_every: float | None = number(
        None,
        "Keep a checkpoint, written every this many seconds of wall time (0: after every chunk of steps), "
        "at the end and on Ctrl-C (default: none; 60 with --checkpoint or --resume).",
        at_least=0.0,
        flags=("--checkpoint-every",),
    ),
    checkpoint: Path | None = typer.Option(
        None, help="Checkpoint file (default OUT.checkpoint.nc next to --out); giving it keeps a checkpoint."
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue from the checkpoint: the same command line plus --resume gives bitwise the uninterrupted run."
    ),
    force: bool = typer.Option(False, "--force", help="Start afresh even if the checkpoint exists (it is replaced)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object."),
    system: str | None = system_option(),
    sets: list[str] | None = set_option(),
    start: str | None = start_option("the start's coordinates (default 0)"),
    velocity: str | None = velocity_option("default 0"),
) -> None:
    """Run one damped simulation of the chain under loads (a moment on one particle by default).

    With --system: the system's flow from --start and --velocity (DOP853), FRAMES states to --out.

    With --checkpoint-every S (or --checkpoint FILE) the fixed-step run keeps a checkpoint,
    OUT.checkpoint.nc by default: its state, step count, frames so far, settings, parameters
    and loads, written atomically every S seconds of wall time, at the end, on Ctrl-C and on an
    error. Run the same command with --resume to continue it; the result is bitwise that of
    the uninterrupted run (with the same --threads). A checkpoint of other parameters, model,
    loads, method, dt, --t-end, --frames or start (--x0, --at) is refused naming what differs;
    an existing one is replaced only with --force. The checkpoint is kept when the run completes.

    Exit status: 0 done, 2 bad input, 3 blow-up, 5 inaccurate, 130 interrupted (saved).
    """
    if system is not None:
        chain_only_or_exit(ctx, ("config", "as_json", "out", "t_end", "frames", "sets", "start", "velocity"))
        return simulate_on_system(
            system, config=config, sets=sets, t_end=t_end, frames=frames, start=start, velocity=velocity, out=out, as_json=as_json
        )
    system_only_or_exit(ctx, ("sets", "start", "velocity"))
    from ..experiments.simulation import simulate as run_simulation
    from ..loads import Loads, Schedule, moment_load

    inputs = {"--config": config, "--x0": x0}
    checkpointing = checkpoint_every is not None or checkpoint is not None or resume
    if force and not checkpointing:
        fail("--force replaces an existing checkpoint: give it with --checkpoint-every or --checkpoint, or leave it out")
    if checkpointing and reference:
        fail(
            "--reference (the adaptive DOP853 reference) takes no fixed steps to checkpoint: "
            "leave out --reference, or --checkpoint-every, --checkpoint and --resume"
        )
    if checkpointing:
        needed_by = "--checkpoint-every" if checkpoint_every is not None else None
        checkpoint = checkpoint_or_exit(checkpoint, out, resume=resume, force=force, inputs=inputs, needed_by=needed_by)
    else:
        outputs_or_exit({"--out": out}, inputs)
    if at is not None and x0 is None:
        fail("--at picks a frame of the run given by --x0; give --x0 RUN.nc")
    params, loads = config_or_exit(config, load)
    t0, start, velocities = 0.0, None, None
    if x0 is not None:
        # The run's chain, frame and loads; loads given here (config, --load, --moment) replace its loads.
        run_params, run_loads, t0, start, velocities = _frame_or_exit(x0, at)
        if config is not None and params != run_params:
            fail(f"--config describes another chain than the run {str(x0)!r}: leave --config out to go on with the run's chain")
        params = run_params
        if not loads and moment is None:
            loads = run_loads
        if not t_end > t0:
            fail(f"--t-end {t_end:g} must be after the start frame's time {t0:g} (the run's time axis goes on)")
    # --moment is the shorthand for a moment on --particle: the paper's 0.1 when no other load is given.
    if moment is None and not loads:
        moment = 0.1
    try:
        if moment is not None:
            schedule = Schedule.ramp(moment, ramp) if ramp > 0 else Schedule.constant(moment)
            loads = Loads([*moment_load(schedule, particle), *loads]).validate(params)
    except ValueError as err:
        fail(str(err))
    step = None if reference else step_for_checks(params, model, dt)
    if step is not None:
        # A run whose moment spins its particle by more than half a turn a step runs and is flagged inaccurate with the
        # step it needs (exit 5); where even that step is beyond the work started, it is refused before the run (the loads
        # on one particle add up).
        spins: dict[int, float] = {}
        for point in loads:
            if point.row == "phi" and params.gamma_phi > 0.0:
                spins[point.particle] = spins.get(point.particle, 0.0) + point.schedule.bound() / params.gamma_phi
        for where, spin in spins.items():
            if spin * step > MAX_TURN_PER_STEP:  # (a zero moment spins nothing)
                needed = MAX_TURN_PER_STEP / spin
                work_or_exit(
                    (t_end - t0) / needed,
                    params.n_particles,
                    f"{t_end - t0:g} time units at the dt <= {needed:.3g} that a moment of {spin * params.gamma_phi:g} on "
                    f"particle {where} needs: |M| / gamma_phi = {spin:.3g} rad per unit time, at most half a turn a step",
                    "a smaller moment",
                )
        span = f"{t_end - t0:g} time units at dt={step:.3g}"
        larger = "a larger --dt" if dt is not None else LARGER_STEP
        work_or_exit((t_end - t0) / step, params.n_particles, span, f"a shorter --t-end, or {larger}")
    bar = progress_bar(f"simulate {model}", "step")
    progress = bar_callback(bar)
    try:
        ds = run_simulation(
            params,
            model,
            loads,
            t_end=t_end,
            t0=t0,
            x0=start,
            v0=velocities,
            dt=dt,
            method=method.value,
            n_frames=frames,
            threads=threads,
            reference=reference,
            progress=progress,
            checkpoint=checkpoint,
            checkpoint_every=60.0 if checkpoint_every is None else checkpoint_every,
            resume=resume,
        )
    except ValueError as err:
        bar.close()
        fail(str(err))
    bar.finish(ds.attrs["status"])
    if x0 is not None:
        ds.attrs["started_from"] = f"{x0} at t = {t0!r}"
    save_dataset(ds, out)
    status = ds.attrs["status"]
    if as_json:
        typer.echo(json.dumps(_summary(ds, params, model, t_end, out)))
    elif status == Status.COMPLETED:
        final = ds.isel(time=-1)
        typer.echo(
            f"{model}: t={float(final.time):g}, phi_0={float(final.phi.sel(particle=particle)):.6g} rad, "
            f"balance error {float(final.balance_error):.3g}" + (f"; wrote {out}" if out else "")
        )
    exit_on(status, ds.attrs["message"])


def _frame_or_exit(path: Path, at: float | None):
    """The chain, loads, time, positions and velocities of a stored frame, or exit 2 saying why not."""
    from ..io import read_dataset, run_frame

    label = f"--x0 {str(path)!r}"
    try:
        return run_frame(read_dataset(path), at, source=label)
    except ValueError as err:
        fail(str(err) if str(err).startswith(label) else f"{label}: {err}")


def _summary(ds, params, model: str, t_end: float, out: Path | None) -> dict[str, Any]:
    final = ds.isel(time=-1)
    energy = {name: finite_or_none(float(final[name])) for name in ("kinetic", "potential", "load_work", "dissipated", "balance_error")}
    return {
        "model": model,
        "params": params.model_dump(),
        "t_end": t_end,
        "t_reached": float(final.time),
        "dt": finite_or_none(float(ds.attrs["dt"])),
        "method": ds.attrs["method"],
        "steps": int(ds.attrs["steps"]),
        "loads": json.loads(ds.attrs["loads_json"]),
        "status": ds.attrs["status"],
        "message": ds.attrs["message"],
        "final": {row: [float(x) for x in final[row].values] for row in ("u", "v", "phi")},
        "energy": energy,
        "accuracy": {
            "balance_relative": finite_or_none(float(ds.attrs["balance_relative"])),
            "rotation_per_step": finite_or_none(float(ds.attrs["rotation_per_step"])),
            "damping_per_step": finite_or_none(float(ds.attrs.get("damping_per_step", float("nan")))),
        },
        "out": str(out) if out else None,
    }
