"""Subcommands of ``beastbt``; each module is imported only when its command runs."""
