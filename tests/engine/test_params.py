"""Tests of engine.params: BuildParams defaults, derived distances and validation."""

from __future__ import annotations

import dataclasses

import pytest

from engine.errors import InvalidParameter
from engine.params import BuildParams


def test_defaults_span_1_50000_to_1_500000() -> None:
    params = BuildParams()
    assert (params.source_scale, params.target_scale) == (50_000.0, 500_000.0)
    assert params.target_mode == "scale"
    assert params.tessellation_per_span == 0
    assert params.resolve_crossings is True


def test_target_tolerance_is_0_1_mm_at_the_target_scale() -> None:
    assert BuildParams().target_tolerance_m == pytest.approx(50.0, rel=1e-12)  # docs/design.md: 50 m at 1:500,000
    assert BuildParams(target_scale=250_000).target_tolerance_m == pytest.approx(25.0, rel=1e-12)


def test_default_spacing_is_1_mm_at_the_source_scale() -> None:
    assert BuildParams().spacing_m == pytest.approx(50.0, rel=1e-12)  # 1 mm at 1:50,000
    assert BuildParams(source_scale=10_000, target_scale=100_000).spacing_m == pytest.approx(10.0, rel=1e-12)


def test_explicit_spacing_wins() -> None:
    assert BuildParams(resample_spacing_m=3.5).spacing_m == 3.5


def test_params_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        BuildParams().source_scale = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "names"),
    [
        ({"source_scale": 0.0}, "source_scale"),
        ({"source_scale": -5.0}, "source_scale"),
        ({"source_scale": float("nan")}, "source_scale"),
        ({"target_scale": float("inf")}, "target_scale"),
        ({"source_scale": 500_000.0, "target_scale": 50_000.0}, "target_scale"),
        ({"source_scale": 50_000.0, "target_scale": 50_000.0}, "target_scale"),
        ({"target_mode": "bogus"}, "target_mode"),
        ({"target_mode": "points"}, "target_points"),
        ({"target_mode": "points", "target_points": 1}, "target_points"),
        ({"resample_spacing_m": 0.0}, "resample_spacing_m"),
        ({"resample_spacing_m": -1.0}, "resample_spacing_m"),
        ({"similarity_levels": 1}, "similarity_levels"),
        ({"scale_levels": 1}, "scale_levels"),
        ({"scale_mapping": "linear"}, "scale_mapping"),
    ],
)
def test_invalid_parameters_raise_naming_the_parameter(kwargs: dict[str, object], names: str) -> None:
    with pytest.raises(InvalidParameter, match=names):
        BuildParams(**kwargs)  # type: ignore[arg-type]


def test_points_mode_with_a_count_is_valid() -> None:
    assert BuildParams(target_mode="points", target_points=2).target_points == 2
