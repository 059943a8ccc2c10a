"""A graded chain has no bands: the infinite chain's dispersion refuses it, naming its factors, rather than
returning the uniform chain's bands as its own."""

from __future__ import annotations

import numpy as np
import pytest

from cosserat_chain.analysis.dispersion import continuum_dispersion, dispersion, finite_modes, parameter_scan, wave_summary
from cosserat_chain.params import ChainParams

N = 3
UNIFORM = ChainParams(N=N)
GRADED = {
    "E1_factors": tuple(np.linspace(0.5, 1.5, 2 * N)),
    "E2_factors": tuple(np.linspace(1.5, 0.5, 2 * N)),
    "m_factors": tuple(np.linspace(0.8, 1.2, 2 * N + 1)),
    "j_factors": tuple(np.linspace(1.2, 0.8, 2 * N + 1)),
}
CALLS = {
    "dispersion": lambda p: dispersion(p, n_q=9),
    "continuum_dispersion": lambda p: continuum_dispersion(p, n_q=9),
    "wave_summary": lambda p: wave_summary(p, n_q=33),
    "parameter_scan": lambda p: parameter_scan(p, "E1", [1.0, 1.2]),
}


@pytest.mark.parametrize("call", CALLS)
@pytest.mark.parametrize("field", GRADED)
def test_every_band_function_refuses_a_graded_chain_naming_the_field(call, field):
    params = UNIFORM.replace(**{field: GRADED[field]})
    count = len(GRADED[field])
    with pytest.raises(ValueError, match=rf"graded: {field} \({count} factors in \[0\.[58], 1\.[25]\]\)") as err:
        CALLS[call](params)
    assert f"params.replace({field}=None)" in str(err.value)
    assert "finite_modes" in str(err.value)


def test_all_the_factors_given_are_named():
    with pytest.raises(ValueError) as err:
        wave_summary(UNIFORM.replace(**GRADED))
    message = str(err.value)
    assert all(name in message for name in GRADED)
    assert "params.replace(E1_factors=None, E2_factors=None, m_factors=None, j_factors=None)" in message


def test_factors_all_alike_are_the_uniform_chain_and_keep_its_bands():
    """E1_factors all 2 fold into E1 = 2 (ChainParams): the chain is uniform and its bands are E1 = 2's, bit for bit."""
    alike = UNIFORM.replace(E1_factors=(2.0,) * (2 * N), m_factors=(0.5,) * (2 * N + 1))
    scaled = UNIFORM.replace(E1=2.0, m=0.5)
    np.testing.assert_array_equal(dispersion(alike).omega2, dispersion(scaled).omega2)
    assert wave_summary(alike).bands == wave_summary(scaled).bands


def test_a_light_particle_vibrates_above_the_uniform_chains_bands():
    """Why the uniform bands are not a graded chain's: one particle of a quarter the mass and inertia
    holds a localized mode far above every band of the uniform chain (8.47 against 4.80), which the
    graded chain's own modes (finite_modes) show."""
    params = ChainParams(N=10)
    factors = np.ones(2 * 10 + 1)
    factors[10] = 0.25
    impurity = params.replace(m_factors=tuple(factors), j_factors=tuple(factors))
    top = max(high for _, high in wave_summary(params).bands.values())
    uniform_modes = finite_modes(params).frequencies
    graded_modes = finite_modes(impurity).frequencies
    assert np.max(uniform_modes) <= top * (1 + 1e-12)
    assert np.max(graded_modes) > 1.5 * top
