"""What tells others a run has ended (``Prepared.after_summary``: the fleet's station) does so once its summary is on
disk, never before: a station's reader that fetches the summary as soon as it hears of the end finds it whole."""

from __future__ import annotations

import io
import json
from typing import Optional

from conftest import REPO


def test_after_summary_is_called_with_the_summary_once_it_is_written(tmp_path):
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    p = prepare(str(REPO / "missions" / "patrol.yaml"),
                RunOptions(record=True, runs_dir=str(tmp_path / "runs"), max_time_s=3.0,
                           summary_path=str(tmp_path / "s.json")))
    seen: list = []

    def ended(summary: Optional[dict]) -> None:
        on_disk = json.loads((p.folder.path / "summary.json").read_text())
        seen.append((summary, on_disk, json.loads((tmp_path / "s.json").read_text())))

    p.after_summary.append(ended)
    p.after_summary.insert(0, lambda summary: 1 / 0)  # one failing does not keep the others from hearing
    returned = execute(p, io.StringIO())
    assert len(seen) == 1
    summary, on_disk, given = seen[0]
    assert summary is returned and on_disk["status"] == given["status"] == returned["status"]
    assert on_disk["sim_time_s"] == returned["sim_time_s"]


def test_an_abandoned_run_says_it_ended_with_no_summary(tmp_path):
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions
    p = prepare(str(REPO / "missions" / "patrol.yaml"), RunOptions(record=True, runs_dir=str(tmp_path / "runs")))
    seen: list = []
    p.after_summary.append(seen.append)
    p.abandon()
    assert seen == [None] and not p.folder.path.exists()
