"""Simulated runs started from the studio (placeholder; filled in next)."""


class Trials:
    """The runs the studio started."""

    def __init__(self, folder) -> None:
        self.folder = folder

    def stop_all(self) -> None:
        """Stop every run still going."""
