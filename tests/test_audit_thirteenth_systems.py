"""The thirteenth outside audit of the open-system kit on user systems no other test holds (H13audA).

A researcher's systems, written here in a few lines: formulas with names SymPy also knows (``E``, ``I``, ``gamma``,
``zeta``, ``pi``, ``lambda``), Greek degrees of freedom and files with errors. Each defect's test fails on the code
before its fix; the others check the numbers against closed forms or an independent NumPy evaluation.
"""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import SYSTEMS_CACHE
from cosserat_chain.cli import app
from cosserat_chain.systems import LatticeSystem
from cosserat_chain.systems.base import SystemDefinitionError
from three_junctions import REFERENCE


@pytest.fixture(autouse=True)
def _cache(monkeypatch):
    """The compiled systems go to the tests' cache folder, not the user's."""
    monkeypatch.setenv("COSSERAT_CHAIN_CACHE", str(SYSTEMS_CACHE))


def rotors(site_energy: str, parameters: dict, *, dofs=("phi",), bond="k*(1 - cos(phi_r - phi_l))", **options):
    """Three free rotors with the site energy ``site_energy`` (a bond of stiffness k = 0.3, damping g = 0.1)."""
    return LatticeSystem(
        sites=3,
        dofs=dofs,
        site_energy=site_energy,
        bond_energy=bond,
        damping=options.pop("damping", "g"),
        parameters={"k": 0.3, "g": 0.1, **parameters},
        name="audit13",
        **options,
    )


@pytest.mark.parametrize("name", ["E", "I", "gamma", "zeta", "beta", "S"])
def test_an_undeclared_name_sympy_knows_is_refused_by_name(name):
    # E was Euler's number, I the imaginary unit (a complex force Numba failed to type at the first force), gamma
    # and zeta SymPy's functions ("unsupported operand type(s) for *: 'FunctionClass' and 'Symbol'").
    with pytest.raises(SystemDefinitionError, match=rf"site_energy uses unknown names \['{name}'\]"):
        rotors(f"1 - cos(phi) - {name}*phi", {})


def test_the_same_names_declared_are_the_parameters_and_pi_stays_the_constant():
    # Every name SymPy knows, declared, is the user's parameter: the forces against NumPy at a random state.
    values = {"E": 0.7, "I": 0.2, "beta": 0.3, "gamma": 0.12, "zeta": 0.45, "pi": 0.5}
    system = rotors(
        "E*(1 - cos(phi)) - (I + beta)*phi + zeta*phi**2/2",
        values,
        bond="pi*(1 - cos(phi_r - phi_l)) + gamma*(phi_r - phi_l)**2/2",
    )
    q = np.random.default_rng(13).uniform(-3, 3, 3)
    bond = np.diff(q)
    tension = values["pi"] * np.sin(bond) + values["gamma"] * bond
    expected = -values["E"] * np.sin(q) + values["I"] + values["beta"] - values["zeta"] * q
    expected[:-1] += tension
    expected[1:] -= tension
    np.testing.assert_allclose(system.forces(q), expected, rtol=0, atol=1e-14)
    undeclared_pi = rotors("1 - cos(phi) - phi/pi", {})
    np.testing.assert_allclose(undeclared_pi.forces(np.zeros(3)), 1 / np.pi, rtol=1e-15)


@pytest.mark.parametrize("formula", ["1 - cos(phi) + sqrt(-1)*phi", "1 - cos(phi) + phi/0"])
def test_a_formula_that_is_not_real_and_finite_is_refused_naming_its_field(formula):
    with pytest.raises(SystemDefinitionError, match=r"site_energy: .* is not a real finite formula"):
        rotors(formula, {})


def test_a_python_keyword_as_a_name_is_refused_saying_so():
    # lambda (a common name for a coupling) made SymPy's parser fail with "invalid syntax".
    with pytest.raises(SystemDefinitionError, match=r"\['lambda'\] are Python keywords"):
        rotors("1 - cos(phi) - lambda*phi", {"lambda": 0.2})


def test_a_mass_that_is_not_positive_is_refused_when_the_system_is_built():
    # It was refused at the first flow or stability, a traceback on the command line (exit 1).
    with pytest.raises(SystemDefinitionError, match="mass of every degree of freedom must be > 0"):
        rotors("1 - cos(phi)", {"m": 0.0}, mass="m")


def test_greek_angles_are_angles_by_default():
    # A rotor written with theta's letter turned no turns: only phi* and theta* were angles by default.
    system = rotors("E*(1 - cos(θ)) - beta*θ", {"E": 0.7, "beta": 0.3}, dofs=("θ",), bond="k*(1 - cos(θ_r - θ_l))")
    assert system.angles.all()
    assert system.coordinates == ("θ_0", "θ_1", "θ_2")


USER_FILE = """
from cosserat_chain.systems import LatticeSystem


def rotors(*, sites=3, m=0.0, coupling="k"):
    return LatticeSystem(sites=sites, site_energy="1 - cos(phi) - I*phi", bond_energy=coupling + "*(1 - cos(phi_r - phi_l))",
                         mass="m", damping="g", parameters={"I": 0.2, coupling: 0.3, "g": 0.1, "m": m})
"""


@pytest.mark.parametrize(
    ("settings", "named"),
    [(("--set", "m=0"), "mass of every degree of freedom must be > 0"), (("--set", "m=1", "--set", "coupling=lambda"), "keywords")],
)
def test_states_on_a_file_with_an_error_exits_2_naming_it(tmp_path, settings, named):
    (tmp_path / "rotors.py").write_text(USER_FILE)
    result = CliRunner().invoke(app, ["states", "--system", f"{tmp_path / 'rotors.py'}:rotors", *settings], terminal_width=200)
    assert result.exit_code == 2, result.output
    assert named in result.output
    assert "Traceback" not in result.output


def test_a_branch_ending_at_a_fold_names_its_parameter_in_the_message():
    # The kit's message read "fold located at lambda = 1" (its own name for the continued parameter), also on the
    # command line and in orbit --out's branch_message.
    from cosserat_chain.numerics.equilibria import continue_equilibria, find_equilibrium
    from cosserat_chain.systems import josephson_array

    branch = continue_equilibria(find_equilibrium(josephson_array(3, I=0.2), np.zeros(3)), "I")
    assert branch.end == "fold"
    assert abs(branch.events[-1].parameter - 1.0) < 1e-10  # sin(phi) = I folds at I = 1
    assert "fold located at I = 1:" in branch.message, branch.message


#: AUTO-07p on three Josephson junctions with unequal critical currents (tests/three_junctions.py at I = 0.8,
#: alpha = 0.21; NTST = 100 and 200 agree to the digits printed here), the rotation continued
#: down in I from 0.8: two period doublings, then the fold of cycles where the rotation stops.
AUTO_PD = (0.47818853487, 0.34441407271)
AUTO_FOLD = 0.25387275522


@pytest.mark.slow
def test_junctions_with_unequal_critical_currents_agree_with_auto07p_and_name_what_is_not_located(tmp_path):
    import re

    import xarray as xr

    out = tmp_path / "orbit.nc"
    result = CliRunner().invoke(
        app,
        ["orbit", "--system", REFERENCE, "--set", "I=0.8", "--set", "alpha=0.21", "--vary", "I", "--period-max", "150", "--out", str(out)],
        terminal_width=200,
    )
    assert result.exit_code == 0, result.output
    located = [float(v) for v in re.findall(r"period_doubling at I = (\S+)", result.output)]
    assert np.allclose(located[:2], AUTO_PD, rtol=0, atol=2e-10), result.output
    (fold,) = (float(v) for v in re.findall(r"fold at I = (\S+)", result.output))
    assert abs(fold - AUTO_FOLD) < 2e-10
    # A multiplier passes -1 within 3e-8 in I of the fold (between the last two orbits before it: an independent
    # DOP853 monodromy has -10.0 there and then a complex pair of modulus 0.16); it was printed "at not located".
    assert "at not located" not in result.output
    with xr.open_dataset(out) as ds:
        assert ds.attrs["branch_message"].startswith("fold located at I = 0.2538727552"), ds.attrs["branch_message"]


def test_a_harmonic_josephson_ring_holds_no_fluxon():
    # docs/systems/josephson.md said the ring "holds trapped fluxons": its closing bond sees the jump of -2 pi itself,
    # so Newton from a fluxon ends on a kink-antikink pair of no net phase (the docs now say so).
    from cosserat_chain.numerics.equilibria import find_equilibrium
    from cosserat_chain.systems import josephson_array

    n, kappa = 12, 0.5
    fluxon = 4 * np.arctan(np.exp((np.arange(n) - n / 2 + 0.5) / np.sqrt(kappa)))
    ring = josephson_array(n, kappa=kappa, boundary="periodic")
    eq = find_equilibrium(ring, fluxon)
    jumps = np.diff(np.append(eq.q, eq.q[0]))
    assert abs(np.sum(np.angle(np.exp(1j * jumps)))) < 1e-12  # no net phase around the ring
    assert ring.energy(eq.q) < ring.energy(fluxon) and np.max(np.abs(jumps)) < np.pi + 1e-9
