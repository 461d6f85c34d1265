"""The station's page at ``/``: for now, where the API is and how to use it (the map page is to come)."""

from __future__ import annotations

PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>beastbt station</title></head>
<body>
<h1>beastbt station</h1>
<p>The robots on the fleet: <a href="/api/robots">/api/robots</a> (JSON).</p>
<p>Send a mission: <code>curl --data-binary @mission.yaml -H 'Content-Type: application/yaml'
http://HOST:PORT/api/robots/NAME/mission</code>. Stop every robot: <code>curl -X POST
http://HOST:PORT/api/estop-all</code>. See docs/fleet.md.</p>
</body></html>
"""


def page() -> str:
    """The station's page (HTML, no script)."""
    return PAGE


__all__ = ["page"]
