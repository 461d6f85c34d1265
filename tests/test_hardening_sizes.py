"""Legal but large files cost time and memory in proportion to their size, and oversized ones are refused at their
place (issue 38, points 3 and 5).

Validating a mission grows linearly with its places (4,000 took 109 s when every place was compared with every
other). The probe's inputs are generated here, never committed as big files; the ones that cost memory run the
public command line in a child under an address-space limit (``beastbt_own_rss``), so a regression fails fast
instead of eating the machine. Timings are in benchmarks/validate_scaling.py; here only ratios with generous bounds.
"""

from __future__ import annotations

import random
import time
from types import SimpleNamespace

from beastbt.core import yaml_source
from beastbt.estimation.geodesy import distance_m
from beastbt.mission import place_neighbours, warnings
from beastbt.mission.model import load_mission
from beastbt.validate import validate_file
from hostile_yaml import many_places


def _pairwise(places: list, far_m: float) -> dict[int, tuple[float, str]]:
    """What the warnings computed before issue 38: every place against every other."""
    out = {}
    for i, p in enumerate(places):
        others = [(distance_m(p.lat, p.lon, o.lat, o.lon), o.name) for j, o in enumerate(places) if j != i]
        if others and all(d > far_m for d, _ in others):
            out[i] = min(others)
    return out


def test_lonely_places_are_those_the_pairwise_comparison_finds():
    rng = random.Random(38)
    for trial in range(40):
        places = []
        for k in range(rng.choice([2, 3, 5, 20, 60])):
            kind = rng.random()
            if kind < 0.5:  # a cluster in Madrid
                lat, lon = 40.4 + rng.uniform(-0.3, 0.3), -3.7 + rng.uniform(-0.3, 0.3)
            elif kind < 0.7:  # swapped
                lat, lon = -3.7 + rng.uniform(-0.01, 0.01), 40.4 + rng.uniform(-0.01, 0.01)
            else:  # anywhere, the poles and the antimeridian included
                lat, lon = rng.uniform(-90, 90), rng.choice([rng.uniform(-180, 180), 179.9, -179.9])
            places.append(SimpleNamespace(name=f"p{k}", lat=lat, lon=lon))
        expected = _pairwise(places, warnings.FAR_PLACE_M)
        got = place_neighbours.lonely_places(places, warnings.FAR_PLACE_M)
        assert got.keys() == expected.keys(), trial
        for i, (d, name) in expected.items():
            assert got[i][1] == name and abs(got[i][0] - d) < 1e-3 * max(1.0, d), trial


def test_many_lonely_places_are_compared_with_numpy_to_the_same_answer():
    places = [SimpleNamespace(name=f"p{i}", lat=-60 + (i % 10) * 1.2, lon=-170 + (i // 10) * 1.2) for i in range(60)]
    assert len(places) > place_neighbours.ROWS_IN_PYTHON
    got = place_neighbours.lonely_places(places, warnings.FAR_PLACE_M)
    expected = _pairwise(places, warnings.FAR_PLACE_M)
    assert got.keys() == expected.keys() and len(got) == 60
    assert all(got[i][1] == expected[i][1] and abs(got[i][0] - expected[i][0]) < 1e-3 for i in expected)


def _distance_calls(monkeypatch, count: int, far_flung: bool, tmp_path) -> int:
    path = tmp_path / f"m{count}.yaml"
    path.write_text(many_places(count, far_flung))
    mission = load_mission(path)
    calls = [0]

    def counted(*args):
        calls[0] += 1
        return distance_m(*args)

    monkeypatch.setattr(warnings, "distance_m", counted)
    monkeypatch.setattr(place_neighbours, "distance_m", counted)
    found = warnings.mission_warnings(mission)
    assert len(found) == (count if far_flung else 0)
    return calls[0]


def test_the_far_place_warnings_measure_a_number_of_distances_linear_in_the_places(monkeypatch, tmp_path):
    # Four times the places: about four times the distances (it was sixteen: every place against every other).
    few, many = (_distance_calls(monkeypatch, n, False, tmp_path) for n in (1000, 4000))
    assert many < 6 * few, (few, many)


def test_a_mission_of_4000_places_validates_in_under_8_times_the_cost_of_1000(tmp_path):
    # Processor time of this process, so a busy machine does not fail it; 16x before (6.5 s against 109 s).
    costs = {}
    for count in (1000, 1000, 4000):  # the first 1000 loads the modules
        path = tmp_path / f"m{count}.yaml"
        path.write_text(many_places(count))
        t0 = time.process_time()
        assert validate_file(str(path)) == []
        costs[count] = time.process_time() - t0
    assert costs[4000] < 8 * costs[1000], costs


def test_a_mission_of_many_places_in_braces_is_composed_by_libyaml():
    # Counting every '{' of 4,000 places made the file look nested too deep for libyaml: PyYAML's composer took
    # it, ten times slower. The real depth is counted now; a really deep file still goes to PyYAML's composer.
    assert yaml_source._compose_fast(many_places(4000)) is not None
    assert yaml_source._compose_fast("a: " + "[" * 300 + "]" * 300 + "\n") is None
    assert yaml_source._compose_fast("a: " + "{b: " * 300 + "1" + "}" * 300 + "\n") is None
