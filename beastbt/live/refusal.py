"""A console control that cannot be carried out now: one exception for the controls and for live tuning."""

from __future__ import annotations


class Refused(Exception):
    """A control that cannot be carried out now: ``status`` is the HTTP status (409, 400) and the message says why."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


__all__ = ["Refused"]
