"""The optional parts of beastbt, imported once so that they register their steps, devices and commands.

Each part lives in its own folder and registers itself with the compiler
(``register_step``), the simulator (``register_sim_device``), the runtime
hooks and the CLI (``COMMANDS``). Importing this module imports them all.
"""
