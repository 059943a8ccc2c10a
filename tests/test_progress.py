"""Progress bars count whole pieces of real work and end at 100 %, or say why they stopped (issue 43, item 5).

The bars show only on a terminal, so every test runs its command with stderr on a
pseudo-terminal and reads what a user would see: the last state of the bar. The commands and
the scripts that draw bars run in the test process (``in_process.on_terminal``, its stderr on
the terminal); the slow tests run ``python -m cosserat_chain`` on one, as a user does.
"""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import textwrap
from collections.abc import Callable

import pytest

import in_process
from cosserat_chain.report import STAGES, ReproduceSettings, reproduce
from in_process import run_script

#: tqdm's counter: ``done/total`` then the percentage, both whole.
COUNT = re.compile(r"(\d+)%\|[^|]*\| (\S+)/(\S+)")


def on_terminal(args: list[str], cwd, timeout: float = 600.0) -> tuple[int, str]:
    """Run ``args`` with stderr on a pseudo-terminal; (exit code, everything written to it)."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 160, 0, 0))  # a terminal 160 columns wide
    process = subprocess.Popen(args, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=follower)
    os.close(follower)
    chunks = []
    while True:
        ready, _, _ = select.select([leader], [], [], timeout)
        if not ready:
            process.kill()
            raise AssertionError(f"{args} wrote nothing for {timeout} s")
        try:
            chunk = os.read(leader, 4096)
        except OSError:  # the follower closed: the process ended
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(leader)
    process.stdout.read()
    return process.wait(timeout=timeout), b"".join(chunks).decode(errors="replace")


def last_bar(screen: str, desc: str) -> str:
    """The bar named ``desc`` as the terminal shows it last (tqdm redraws the line after a carriage return)."""
    states = [s for s in re.split(r"[\r\n]", screen) if s.strip().startswith(desc)]
    assert states, f"no bar {desc!r} in {screen!r}"
    return states[-1]


def counts(bar: str) -> tuple[int, str, str]:
    match = COUNT.search(bar)
    assert match, bar
    return int(match.group(1)), match.group(2), match.group(3)


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "cosserat_chain", *args]


def script(tmp_path, body: str) -> Callable[[], int]:
    """The script drawing bars as ``body`` says, run in this process: its exit code (its traceback if it failed)."""
    path = tmp_path / "bar.py"
    path.write_text("from cosserat_chain.cli.common import bar_callback, progress_bar\n" + textwrap.dedent(body))

    def run() -> int:
        code, _, failure = run_script(path, tmp_path)
        assert failure is None, failure
        return code

    return run


def test_a_bar_of_whole_counts_ends_at_its_total(tmp_path):
    code, screen = in_process.on_terminal(
        script(
            tmp_path,
            """
            bar = progress_bar("steps", "step")
            progress = bar_callback(bar)
            for done in range(0, 2001, 250):
                progress(float(done), 2000.0)
            bar.finish("completed")
            """,
        ),
        tmp_path,
    )
    assert code == 0
    assert counts(last_bar(screen, "steps")) == (100, "2000", "2000")


def test_work_that_ends_before_its_cap_ends_at_100_percent_and_says_why(tmp_path):
    """A continuation capped at 200 points that ends at a fold after 31 is done: 31/31, not 15 %."""
    code, screen = in_process.on_terminal(
        script(
            tmp_path,
            """
            bar = progress_bar("orbit", "orbit")
            progress = bar_callback(bar)
            for done in range(1, 32):
                progress(done, 200)
            bar.finish(note="the branch ended: fold")
            """,
        ),
        tmp_path,
    )
    assert code == 0
    bar = last_bar(screen, "orbit")
    assert counts(bar) == (100, "31", "31") and "the branch ended: fold" in bar


def test_a_quantity_that_is_not_a_count_is_shown_as_whole_percent(tmp_path):
    code, screen = in_process.on_terminal(
        script(
            tmp_path,
            """
            import math
            bar = progress_bar("critical", "rad")
            progress = bar_callback(bar)
            for phi in (0.1, 1.3, 4.9, 6.1):
                progress(phi, 2 * math.pi)
            bar.finish()
            """,
        ),
        tmp_path,
    )
    assert code == 0
    assert counts(last_bar(screen, "critical")) == (100, "100", "100")
    assert not re.search(r"\d\.\d+/", screen)  # never a fractional count


def test_a_bar_that_stops_says_why_and_keeps_its_count(tmp_path):
    code, screen = in_process.on_terminal(
        script(
            tmp_path,
            """
            bar = progress_bar("simulate", "step")
            progress = bar_callback(bar)
            progress(300, 1000)
            bar.finish("blew_up")
            bar = progress_bar("rotate", "turn")
            try:
                bar_callback(bar)(2, 10)
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                bar.close()
            """,
        ),
        tmp_path,
    )
    assert code == 0
    stopped = last_bar(screen, "simulate")
    assert counts(stopped) == (30, "300", "1000") and "stopped: blew_up" in stopped
    interrupted = last_bar(screen, "rotate")
    assert counts(interrupted) == (20, "2", "10") and "stopped: KeyboardInterrupt" in interrupted


#: The commands whose bars the three tests below read, run one after the other in this process on the terminal (as
#: ``python -m cosserat_chain`` runs each: ``in_process.run_command``), each between two markers.
_ON_TERMINAL = {
    "simulate": ["simulate", "--moment", "0.1", "--t-end", "30"],
    "animate": ["animate", "--t-end", "20", "--frames", "5", "--out", "a.gif"],
    "rotate": ["rotate", "--moment", "0.3", "--turns", "100", "--t-max", "5"],
}


def _commands_in_turn() -> int:
    for name, args in _ON_TERMINAL.items():
        print(f"<<<START {name}>>>", file=sys.stderr, flush=True)
        code = in_process.run_command(args)
        print(f"<<<EXIT {name} {code}>>>", file=sys.stderr, flush=True)
    return 0


@pytest.fixture(scope="module")
def terminal_runs(tmp_path_factory) -> dict[str, tuple[int, str]]:
    """Command -> (its exit code, what it wrote to the terminal) of the commands of ``_ON_TERMINAL``."""
    code, screen = in_process.on_terminal(_commands_in_turn, tmp_path_factory.mktemp("terminal"))
    assert code == 0, screen[-3000:]
    runs = {}
    for name in _ON_TERMINAL:
        match = re.search(rf"<<<START {name}>>>(.*)<<<EXIT {name} (-?\d+)>>>", screen, flags=re.S)
        assert match, f"{name} did not finish: {screen[-3000:]}"
        runs[name] = (int(match.group(2)), match.group(1))
    return runs


def test_simulate_counts_whole_steps_to_100_percent(terminal_runs):
    code, screen = terminal_runs["simulate"]
    assert code == 0
    percent, done, total = counts(last_bar(screen, "simulate nonlinear"))
    assert percent == 100 and done == total and done.isdigit() and int(done) > 100


def test_animate_counts_its_frames_to_100_percent(terminal_runs):
    code, screen = terminal_runs["animate"]
    assert code == 0
    assert counts(last_bar(screen, "animate"))[1:] == ("5", "5") and counts(last_bar(screen, "animate"))[0] == 100
    assert counts(last_bar(screen, "simulate nonlinear"))[0] == 100


def test_rotate_at_its_time_limit_says_it_stopped_there(terminal_runs):
    code, screen = terminal_runs["rotate"]
    assert code == 4
    bar = last_bar(screen, "rotate nonlinear")
    assert "stopped: time_limit" in bar and counts(bar)[1:] == ("1", "100")


@pytest.mark.slow  # a continuation of some sixty orbits; a bar whose work ends before its cap is tested quickly above
def test_orbit_down_to_ends_at_100_percent_where_the_branch_ends(tmp_path):
    """The continuation is capped in points; it ends at the fold of cycles near M = 0.164 (61 orbits)."""
    code, screen = on_terminal(cli("orbit", "--model", "sine", "--moment", "0.22", "--turns", "1", "--down-to", "0.1"), tmp_path)
    assert code == 0
    bar = last_bar(screen, "orbit sine")
    percent, done, total = counts(bar)
    assert percent == 100 and done == total and int(done) > 10 and "the branch ended" in bar


def test_the_reports_progress_reaches_every_stage_and_ends_at_the_total(tmp_path):
    calls = []
    reproduce(tmp_path, settings=ReproduceSettings(), stages=["waves", "errata"], progress=lambda *call: calls.append(call))
    assert [(done, total) for _, done, total in calls if not _inner(_)] == [(0, 2), (1, 2), (2, 2)]
    assert all(isinstance(done, int) and isinstance(total, int) for _, done, total in calls)


def _inner(name: str) -> bool:
    return ":" in name


@pytest.mark.slow
def test_reproduce_on_a_terminal_ends_at_100_percent(tmp_path):
    config = tmp_path / "quick.toml"
    config.write_text(
        "[reproduce]\ndm = 0.05\nturns = 15\nn_list = [3, 10]\nlong_n_list = [3, 10]\nsnapshot_times = [20.0, 21.0]\n"
        "animation_frames = 10\norbit_down_to = 0.21\ndiagram_damping = { sine = [0.5], nonlinear = [] }\n"
    )
    code, screen = on_terminal(cli("reproduce", "--out", str(tmp_path / "report"), "--config", str(config)), tmp_path)
    assert code == 0
    percent, done, total = counts(last_bar(screen, "reproduce"))
    assert percent == 100 and done == total == str(len(STAGES))
    # While the state diagram computes, the bar says how far it is.
    assert re.search(r"state_map: sine \d+/1 values", screen)
