"""The console's state as JSON (beastbt/live/console_server.py state_json): what the page parses."""

from __future__ import annotations

import json
import math

import numpy as np

from beastbt.live.console_server import state_json


def test_a_state_reads_back_the_same_and_a_nan_is_null():
    state = {"mission": "patrol", "time_s": 1.25, "pose": {"x": np.float64(0.5), "y": -1.0},
             "obstacles": {"scan": [[0.1, 0.2], [1.5, -2.25]]}, "battery": {"volts": math.nan}, "tree": []}
    back = json.loads(state_json(state))  # strict JSON: a NaN would not parse in the page
    assert back == {"mission": "patrol", "time_s": 1.25, "pose": {"x": 0.5, "y": -1.0},
                    "obstacles": {"scan": [[0.1, 0.2], [1.5, -2.25]]}, "battery": {"volts": None}, "tree": []}


def test_what_orjson_does_not_take_is_still_written():
    class Odd(float):
        """A float subclass (orjson refuses them)."""

    assert json.loads(state_json({"v": Odd(2.5)})) == {"v": 2.5}
