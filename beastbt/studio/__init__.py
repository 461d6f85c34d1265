"""The mission studio: ``beastbt studio`` serves a page to write, place, check and try missions (docs/studio.md).

``files`` is the FOLDER view (paths kept inside it, versions, saves with a
``.bak``), ``edits`` the round-trip edits the map makes to a mission's text,
``templates`` the new missions, ``analysis`` what the page shows of a text
(problems, tree, map), ``trial`` the simulated runs, ``server`` the HTTP API.
"""
