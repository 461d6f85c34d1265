"""beastbt: declarative YAML missions compiled to behaviour trees, for small ground robots and their simulator."""

__version__ = "0.1.0"
