"""The DeFT validator and its edge cases."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from astaa_deft.analysis.deft.validator import compare, identical


def line(n, dt=0.1, t0=0.0, y=0.0, dx=1.0):
    return [(i * dx, y, t0 + i * dt) for i in range(n)]


def test_identical_trajectories_distance_zero():
    c = compare(line(10), line(10))
    assert c.distance == 0.0 and c.max_error == 0.0 and c.points == 10 and c.how == "interpolated"


def test_lockstep_euclidean_distance_and_max_error():
    c = compare(line(5, y=0.0), line(5, y=0.3))
    assert c.max_error == pytest.approx(0.3)
    assert c.distance == pytest.approx(math.sqrt(5 * 0.09))


def test_interpolates_replayed_onto_recorded_timestamps():
    replayed = [(0.0, 0.0, 0.0), (2.0, 0.0, 0.2)]
    recorded = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.1), (2.0, 0.0, 0.2)]
    assert compare(replayed, recorded).distance == pytest.approx(0.0)


def test_only_the_common_span_is_compared():
    replayed = line(10, t0=0.5)  # starts 0.5 s later
    recorded = line(10, t0=0.0)
    c = compare(replayed, recorded)
    assert c.points == 5  # recorded points at 0.5 … 0.9 s
    assert c.max_error == pytest.approx(5.0)  # replayed is 5 m behind at the same time


def test_both_empty_match_one_empty_does_not():
    assert compare([], []).distance == 0.0
    assert compare([], line(3)).distance == math.inf
    assert compare(line(3), []).distance == math.inf


def test_single_point_compares_first_points():
    c = compare([(1.0, 1.0, 5.0)], [(1.0, 2.0, 0.0), (3.0, 3.0, 1.0)])
    assert c.how == "first point" and c.distance == pytest.approx(1.0)


def test_no_overlap_compares_first_points():
    c = compare(line(3, t0=10.0), line(3, t0=0.0))
    assert c.how == "first point" and c.distance == 0.0


def test_non_monotonic_times_compare_index_by_index():
    replayed = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.1)]
    c = compare(replayed, line(2))
    assert c.how == "index" and c.points == 2


def test_non_finite_points_match_only_if_identical():
    bad = [(float("nan"), 0.0, 0.0), (1.0, 0.0, 0.1)]
    assert compare(bad, list(bad)).distance == 0.0
    assert compare(bad, line(2)).distance == math.inf


coordinates = st.one_of(st.floats(-1e6, 1e6), st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0]))
trajectories = st.lists(st.tuples(coordinates, coordinates,
                                  st.one_of(st.floats(0, 1e4), st.sampled_from([1.0, math.nan]))), max_size=8)


@settings(max_examples=300, deadline=None)
@given(trajectories, st.booleans())
def test_identical_is_compare_of_a_trajectory_with_itself(points, increasing):
    if increasing:  # the common case: strictly increasing times (else compare goes index by index)
        points = [(x, y, float(i)) for i, (x, y, _) in enumerate(points)]
    assert identical(points) == compare(points, list(points))
