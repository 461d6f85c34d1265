"""The fleet on Eclipse Zenoh: robots that report to a station and take its missions and commands.

One module per concept: :mod:`~beastbt.fleet.keys` (the key space, a public
contract), :mod:`~beastbt.fleet.config` (``--fleet`` and ``--fleet-config``
to a Zenoh configuration), :mod:`~beastbt.fleet.agent` (the robot's side: its
state, events, liveliness and command queryables), :mod:`~beastbt.fleet.supervision`
(the ``fleet:`` section: hold while the station is gone),
:mod:`~beastbt.fleet.station` (the router and its HTTP API) and :mod:`~beastbt.fleet.shared_world`
(simulated robots in one world, each an obstacle in the others'). See docs/fleet.md.
"""
