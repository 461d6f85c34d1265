"""Subcommands of ``beastbt`` beyond run, validate and tree; each module is imported only when its command runs."""
