"""The tick loop of ``session.execute``: what it does around the ticks."""

from __future__ import annotations

import gc
import io

from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute
from conftest import REPO


def test_setup_objects_are_kept_out_of_full_collections_during_the_loop_and_given_back(tmp_path):
    # A full collection walking every module, tree node and driver can pause a tick for tens of ms; the
    # loop freezes what exists when it starts, so collections walk only what the run makes.
    assert gc.get_freeze_count() == 0
    p = prepare(str(REPO / "missions" / "patrol.yaml"), RunOptions(seed=1, max_time_s=1.0, record=False))
    seen: list[int] = []
    p.run.recorders.append(lambda record: seen.append(gc.get_freeze_count()))
    execute(p, io.StringIO())
    assert len(seen) == 21 and min(seen) > 10_000  # every tick ran with the set-up frozen
    assert gc.get_freeze_count() == 0  # and it is handed back: later garbage of those objects is collected
