"""Hostile YAML texts shared by the input tests and benchmarks/input_limits.py (no pytest import, so the
benchmark's parent process stays small and the children's peak RSS is their own)."""

from __future__ import annotations


def laughs(levels: int, width: int = 10, indent: str = "") -> str:
    """A 'billion laughs' block: ``levels`` anchors, each a list of ``width`` aliases of the one before."""
    lines = [f"{indent}l0: &l0 [" + ", ".join(['"lol"'] * width) + "]"]
    for i in range(1, levels):
        lines.append(f"{indent}l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def million_waits() -> str:
    """A mission whose steps, with the aliases expanded, are 10^6 waits, written in 60 lines."""
    text = "mission: waits\ntasks:\n  t0: &t0\n" + "".join("    - wait: 1 s\n" for _ in range(10))
    for i in range(1, 6):
        text += f"  t{i}: &t{i}\n" + "".join(f"    - sequence: *t{i - 1}\n" for _ in range(10))
    return text + "steps:\n  - sequence: *t5\n"


def many_places(count: int, far_flung: bool = False) -> str:
    """A legal mission of ``count`` GPS places written ``{lat: .., lon: ..}`` and a route through all of them (issue
    38: 4,000 of them took 109 s to validate). Near each other in a 100-column grid 11 m apart, or, ``far_flung``,
    1.2 degrees apart over the globe (every place far from every other: a warning each)."""
    step = 1.2 if far_flung else 1e-4
    south, west = (-60.0, -170.0) if far_flung else (40.4, -3.7)
    lines = ["mission: many_places", "places:"]
    lines += [f"  p{i}: {{lat: {south + (i % 100) * step:.5f}, lon: {west + (i // 100) * step:.5f}}}"
              for i in range(count)]
    lines += ["steps:", "  - route: {places: [" + ", ".join(f"p{i}" for i in range(count)) + "]}"]
    return "\n".join(lines) + "\n"
