"""Round-trip edits (placeholder; filled in next)."""


class EditRefused(Exception):
    """An edit that cannot be made."""

    def where(self) -> dict:
        """Line and column of the problem, when known."""
        return {}


def apply_edit(text: str, edit: dict) -> str:
    """Apply one edit."""
    raise NotImplementedError
