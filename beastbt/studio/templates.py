"""New missions from templates (placeholder; filled in next)."""
from typing import NamedTuple


class Template(NamedTuple):
    """A template's title and one-line description."""
    title: str
    description: str


TEMPLATES: dict = {}


def template_text(name: str, body: dict) -> str:
    """The text of a new mission from template ``name``."""
    raise NotImplementedError
