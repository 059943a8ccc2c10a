"""ChainParams: defaults, derived coefficients and validation messages."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from cosserat_chain import ChainParams
from cosserat_chain.io import load_params, params_from_mapping


def test_paper_defaults_and_resolved_inertia(paper):
    assert (paper.E1, paper.E2, paper.h, paper.a, paper.b, paper.N) == (1.0, 1.0, 1.0, 0.2, 0.2, 3)
    assert paper.n_particles == 7
    assert paper.j == pytest.approx(paper.m * (paper.a**2 + paper.b**2) / 3)
    assert ChainParams(m=3.0).j == pytest.approx(3.0 * 0.08 / 3)


def test_derived_coefficients_follow_the_geometry(paper):
    d2 = (paper.h - 2 * paper.a) ** 2 + 4 * paper.b**2
    assert paper.d == pytest.approx(math.sqrt(d2))
    assert paper.D1 == pytest.approx(paper.E1 - paper.h**2 / d2 * paper.E2)
    assert paper.D2 == pytest.approx(4 * paper.h**2 / d2 * paper.E2)
    # Section 3 prints D1 = E1 - 2 (h/d)^2 E2, which differs (docs/errata.md).
    assert paper.D1 != pytest.approx(paper.E1 - 2 * paper.h**2 / d2 * paper.E2)


@pytest.mark.parametrize(
    ("field", "value", "rule"),
    [
        ("E1", 0.0, "> 0"),
        ("E1", -1.0, "> 0"),
        ("E2", -0.1, ">= 0"),
        ("h", 0.0, "> 0"),
        ("b", -0.2, "> 0"),
        ("m", 0.0, "> 0"),
        ("j", -1.0, "> 0"),
        ("gamma_u", -1.0, ">= 0"),
        ("gamma_v", -1.0, ">= 0"),
        ("gamma_phi", -1.0, ">= 0"),
        ("N", 0, ">= 1"),
        ("a", 0.5, "h/2"),
        ("a", 0.0, "h/2"),
    ],
)
def test_invalid_values_name_field_value_and_rule(field, value, rule):
    with pytest.raises(ValidationError) as err:
        ChainParams(**{field: value})
    text = str(err.value)
    assert field in text and repr(value) in text and rule in text


@pytest.mark.parametrize("field", ["E1", "h", "a", "gamma_phi", "j"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_values_are_rejected(field, value):
    with pytest.raises(ValidationError, match=field):
        ChainParams(**{field: value})


def test_non_integer_N_is_rejected():
    with pytest.raises(ValidationError, match="N"):
        ChainParams(N=3.5)


def test_unknown_config_key_is_named(tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text("E1 = 2.0\nE_2 = 1.0\n")
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['E_2'\].*allowed keys: E1, E2"):
        load_params(path)


def test_config_file_sets_fields(tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text("E2 = 0.5\nN = 10\ngamma_phi = 0.0\n")
    params = load_params(path)
    assert (params.E2, params.N, params.gamma_phi) == (0.5, 10, 0.0)
    assert params_from_mapping({"a": 0.1}).a == 0.1
