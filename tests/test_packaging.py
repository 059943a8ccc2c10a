"""The package as a researcher installs it: a wheel and an sdist that PyPI accepts, and a CLI that runs from the wheel
outside the source tree (issue 43, item 8).

The build runs as CI runs it (``python -m build``: the sdist first, the wheel built from
the unpacked sdist, so a file the sdist forgets fails here). The wheel goes into a fresh
virtual environment in a temporary folder, without its dependencies from the network:
the environment sees the running one's packages through a path file (whose own path files,
this checkout's editable install among them, are not processed), so ``cosserat_chain``
can only come from the wheel. Every requirement the wheel declares is checked to be met
there, then the CLI runs from that environment's ``bin``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import tarfile
import tomllib
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
VERSION = PROJECT["version"]

pytestmark = pytest.mark.slow


def run(args: list, cwd: Path, **env: str) -> subprocess.CompletedProcess:
    result = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=900, env={**os.environ, **env})
    assert result.returncode == 0, f"{args}: {result.stdout[-2000:]}\n{result.stderr[-3000:]}"
    return result


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    run([sys.executable, "-m", "build", "--outdir", out, ROOT], cwd=ROOT)
    return out


@pytest.fixture(scope="module")
def fresh(dist, tmp_path_factory) -> Path:
    """A new virtual environment outside the source tree with the wheel installed; its folder."""
    env = tmp_path_factory.mktemp("fresh") / "venv"
    run([sys.executable, "-m", "venv", env], cwd=env.parent)
    python = env / "bin" / "python"
    site = run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=env.parent).stdout.strip()
    # The running environment's packages (the dependencies), after the fresh site-packages on sys.path.
    Path(site, "dependencies.pth").write_text(
        "\n".join(dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])) + "\n"
    )
    run([python, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", next(dist.glob("*.whl"))], cwd=env.parent)
    return env


def test_twine_accepts_the_wheel_and_the_sdist(dist):
    files = sorted(dist.iterdir())
    assert [f.name for f in files] == [f"cosserat_chain-{VERSION}-py3-none-any.whl", f"cosserat_chain-{VERSION}.tar.gz"]
    checked = run([sys.executable, "-m", "twine", "check", "--strict", *files], cwd=dist)
    assert checked.stdout.count("PASSED") == 2


def test_the_wheel_declares_the_projects_metadata_and_holds_only_the_package(dist):
    wheel = zipfile.ZipFile(next(dist.glob("*.whl")))
    names = wheel.namelist()
    assert f"cosserat_chain-{VERSION}.dist-info/licenses/LICENSE" in names and "cosserat_chain/py.typed" in names
    assert all(n.startswith(("cosserat_chain/", f"cosserat_chain-{VERSION}.dist-info/")) for n in names)
    assert not [n for n in names if "__pycache__" in n]
    meta = Parser().parsestr(wheel.read(f"cosserat_chain-{VERSION}.dist-info/METADATA").decode())
    assert meta["Name"] == "cosserat-chain" and meta["Version"] == VERSION and meta["License-Expression"] == "MIT"
    assert sorted(meta.get_all("Classifier")) == sorted(PROJECT["classifiers"])
    # No project URL until the repository and the docs are published (docs/releasing.md): none points at a placeholder.
    assert meta.get_all("Project-URL") is None and "urls" not in PROJECT
    assert "OS Independent" not in str(PROJECT["classifiers"]), "io uses fcntl, pwd and fork: POSIX only"
    declared = [r for r in meta.get_all("Requires-Dist") if "extra ==" not in r]
    assert sorted(r.replace(" ", "") for r in declared) == sorted(r.replace(" ", "") for r in PROJECT["dependencies"])
    assert "cosserat-chain = cosserat_chain.cli:app" in wheel.read(f"cosserat_chain-{VERSION}.dist-info/entry_points.txt").decode()


def test_the_sdist_carries_what_a_researcher_reads_and_cites(dist):
    names = {n.split("/", 1)[1] for n in tarfile.open(next(dist.glob("*.tar.gz"))).getnames() if "/" in n}
    assert {
        "README.md",
        "LICENSE",
        "CHANGELOG.md",
        "CITATION.cff",
        "pyproject.toml",
        "docs/releasing.md",
        "src/cosserat_chain/cli/common.py",
    } <= names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".nc")]


def test_every_requirement_of_the_wheel_is_met_in_the_fresh_environment(fresh):
    check = """
import json, sys
from importlib.metadata import requires, version
from packaging.requirements import Requirement
unmet = []
for line in requires("cosserat-chain"):
    requirement = Requirement(line)
    if requirement.marker is not None and not requirement.marker.evaluate({"extra": ""}):
        continue
    if not requirement.specifier.contains(version(requirement.name), prereleases=True):
        unmet.append(line)
print(json.dumps(unmet))
"""
    assert json.loads(run([fresh / "bin" / "python", "-c", check], cwd=fresh.parent).stdout) == []


def test_the_cli_runs_from_the_wheel_outside_the_source_tree(fresh, tmp_path):
    where = run([fresh / "bin" / "python", "-c", "import cosserat_chain; print(cosserat_chain.__file__)"], cwd=tmp_path).stdout.strip()
    assert Path(where).is_relative_to(fresh) and not Path(where).is_relative_to(ROOT)
    cli = fresh / "bin" / "cosserat-chain"
    assert run([cli, "--version"], cwd=tmp_path).stdout.strip() == f"cosserat-chain {VERSION}"
    # A tiny computation: the sine chain's M_c is its inverse compliance (README: 0.203960948396095).
    result = json.loads(run([cli, "critical", "--model", "sine", "--json"], cwd=tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "numba")).stdout)
    assert result["models"]["sine"]["M_c"] == pytest.approx(0.203960948396095, rel=1e-12)
