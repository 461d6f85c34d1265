"""``beastbt doctor``: check every device of a robot profile before the first run, without moving anything."""

from __future__ import annotations

import argparse
import sys

EXIT_HEALTHY, EXIT_SOMETHING_FAILED, EXIT_INVALID = 0, 1, 2


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``beastbt doctor``."""
    p.add_argument("--robot", default="ugv_beast", metavar="PROFILE",
                   help="robot profile: a name in robots/ or a YAML file (default: ugv_beast)")


def plural(count: int, word: str) -> str:
    """``1 check``, ``2 checks``: a count and its noun, in the singular for one."""
    return f"{count} {word}{'' if count == 1 else 's'}"


def command(args: argparse.Namespace) -> int:
    """Probe the profile's devices; one OK/WARN/FAIL line each; exit 0 only if nothing failed."""
    from beastbt.core.errors import InvalidInput
    from beastbt.robot.doctor import FAIL, WARN, diagnose
    from beastbt.robot.profile import load_profile
    try:
        profile = load_profile(args.robot)
    except InvalidInput as exc:
        print(exc.format(), file=sys.stderr)
        return EXIT_INVALID
    if profile.name == "sim":
        print("beastbt doctor: the 'sim' profile is the simulator: it has no devices to check; "
              "name your robot's profile with --robot (e.g. --robot ugv_beast)")
        return EXIT_HEALTHY
    print(f"beastbt doctor: robot '{profile.name}' ({profile.file or args.robot}); nothing will move")
    findings = diagnose(profile)
    for finding in findings:
        print(finding.line(), flush=True)
    failed = sum(f.level == FAIL for f in findings)
    warned = sum(f.level == WARN for f in findings)
    if not findings:
        print("this profile has no devices to check (the simulator?)")
    print(f"{plural(len(findings), 'check')}: {failed} failed, {plural(warned, 'warning')}")
    return EXIT_SOMETHING_FAILED if failed else EXIT_HEALTHY
