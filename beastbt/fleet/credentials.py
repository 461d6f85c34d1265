"""``beastbt station --init-keys DIR``: a fleet's own CA, the station's and the robots' certificates, two Zenoh configs.

Written with the ``openssl`` command (no Python dependency for a job done
once): ``ca.crt``/``ca.key`` (the fleet's certificate authority; keep
``ca.key`` off the robots), ``station.crt``/``.key`` (common name
``station``, valid for ``localhost``, ``127.0.0.1`` and each ``--host``),
``robot.crt``/``.key`` (common name ``robot``, for every robot), and
``station.json5`` and ``robot.json5``: standard Zenoh configurations for
mutual TLS (each side proves itself with a certificate of this CA; no other
transport is accepted) with Zenoh's access control on the router: a robot
may publish its state and events, declare its liveliness token and its
queryables, answer queries, hear the stop-all and the simulated robots' poses the station relays, and
nothing else; only the
station queries (commands, missions) and puts the stop-all. ``README.txt``
says how to use them.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Sequence

VALID_DAYS = 3650
"""How long the certificates are valid (days): a classroom's robots outlive a year."""
ROBOT_INGRESS = [
    (["put"], ["beastbt/*/state", "beastbt/*/events"]),
    (["declare_queryable"], ["beastbt/*/cmd/*", "beastbt/*/mission"]),
    (["reply"], ["beastbt/**"]),
    (["declare_subscriber"], ["beastbt/fleet/estop", "beastbt/fleet/sim/poses"]),
    (["liveliness_token"], ["beastbt/*/alive"]),
    (["declare_liveliness_subscriber", "liveliness_query"], ["beastbt/fleet/station"]),
]
"""What a robot may send the router (message kinds, key expressions): everything else from it is dropped."""


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, text=True)


def _leaf(folder: Path, name: str, hosts: Sequence[str], days: int, common_name: str = "") -> None:
    """A key and a certificate (``name.key``, ``name.crt``) signed by the fleet's CA, for ``common_name`` (default
    ``name``), valid for ``hosts``."""
    alt = ",".join(f"IP:{h}" if _is_ip(h) else f"DNS:{h}" for h in hosts)
    ext = folder / f"{name}.ext"
    ext.write_text("basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature,keyEncipherment\n"
                   "extendedKeyUsage=serverAuth,clientAuth\n" + (f"subjectAltName={alt}\n" if alt else ""))
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", f"{name}.key", cwd=folder)
    _openssl("req", "-new", "-key", f"{name}.key", "-subj", f"/CN={common_name or name}", "-out", f"{name}.csr",
             cwd=folder)
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.crt", "-CAkey", "ca.key", "-CAcreateserial",
             "-days", str(days), "-sha256", "-extfile", ext.name, "-out", f"{name}.crt", cwd=folder)
    (folder / f"{name}.csr").unlink()
    ext.unlink()


def _is_ip(host: str) -> bool:
    import ipaddress
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        return False


def _robot_rules(prefix: str, name: str) -> list[dict]:
    """The access rules of robot ``name`` (``*``: any robot): its own keys only, and the fleet's."""
    own = f"beastbt/{name}/"
    # each in both flows: what a robot may send, and its echo the router must be able to send to it
    return [{"id": f"{prefix}-{i}", "messages": messages, "flows": ["ingress", "egress"], "permission": "allow",
             "key_exprs": [e.replace("beastbt/*/", own).replace("beastbt/**", own + "**") for e in exprs]}
            for i, (messages, exprs) in enumerate(ROBOT_INGRESS)]


def station_json5(folder: Path, listen: str, robots: Sequence[str] = ()) -> dict:
    """The station's Zenoh configuration (a router, mutual TLS only, access control for robots).

    Without ``robots`` every robot has the common name ``robot`` and may use any robot's keys; with them,
    each robot has its own certificate (common name: its name) and may use its own keys only.
    """
    groups = [(f"robot-{n}", n, _robot_rules(f"robot-{n}", n)) for n in robots] or [
        ("robots", "robot", _robot_rules("robot", "*"))]
    rules = [rule for _, _, group in groups for rule in group]
    rules.append({"id": "to-robots", "messages": ["put", "delete", "query", "reply", "declare_subscriber",
                                                  "declare_queryable", "liveliness_token", "liveliness_query",
                                                  "declare_liveliness_subscriber"],
                  "flows": ["egress"], "permission": "allow", "key_exprs": ["beastbt/**"]})
    return {
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": str(folder / "ca.crt"),
            "listen_private_key": str(folder / "station.key"), "listen_certificate": str(folder / "station.crt"),
            "enable_mtls": True}}},
        "access_control": {
            "enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": [{"id": subject, "cert_common_names": [cn]} for subject, cn, _ in groups],
            "policies": [{"rules": [r["id"] for r in group] + ["to-robots"], "subjects": [subject]}
                         for subject, _, group in groups]},
    }


def robot_json5(folder: Path, connect: str, stem: str = "robot") -> dict:
    """A robot's Zenoh configuration (a peer connecting to the station by mutual TLS only), with the key and
    certificate ``stem.key``, ``stem.crt``."""
    from beastbt.fleet.config import OPEN_TIMEOUT_MS, RETRY
    return {
        "mode": "peer",
        "listen": {"endpoints": []},
        "connect": {"endpoints": [connect], "timeout_ms": OPEN_TIMEOUT_MS, "exit_on_failure": False, "retry": RETRY},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": str(folder / "ca.crt"),
            "connect_private_key": str(folder / f"{stem}.key"), "connect_certificate": str(folder / f"{stem}.crt"),
            "enable_mtls": True, "verify_name_on_connect": True}}},
    }


HOWTO = """The fleet's keys (beastbt station --init-keys), and how to use them.

On the station:
    beastbt station --fleet-config {folder}/station.json5 --listen tls/0.0.0.0:7447
On each robot (copy ca.crt, robot.crt, robot.key and robot.json5 to it, and fix the paths in robot.json5;
with --robot-name NAME, robot-NAME.crt, .key and .json5 instead, each to its own robot):
    beastbt serve --robot PROFILE --fleet-config robot.json5 --fleet tls/STATION:7447 [--name NAME]

STATION must be a name or address the station's certificate is valid for: {hosts}
(make the keys again with --host NAME for another one). Keep ca.key on this computer only: whoever
has it can make certificates the fleet trusts. Only TLS with a certificate of this CA is accepted;
a robot may publish its own state and events and answer the station, and only the station
may command robots, send missions or stop them all (Zenoh's access control, in station.json5).
"""


def init_keys(folder: Path, hosts: Sequence[str] = (), listen: str = "tls/127.0.0.1:7447",
              days: int = VALID_DAYS, robots: Sequence[str] = ()) -> list[Path]:
    """Write the CA, the certificates, ``station.json5``, ``robot.json5`` and ``README.txt`` into ``folder``.

    With ``robots`` (names), each robot gets its own ``robot-NAME.crt``/``.key``/``.json5`` instead, and may
    use only its own keys (it cannot speak for another robot).

    ``FileExistsError`` when ``folder`` already holds a CA (keys are never overwritten: robots hold them).
    """
    folder = folder.resolve()
    folder.mkdir(parents=True, exist_ok=True)
    if (folder / "ca.key").exists():
        raise FileExistsError(f"{folder} already holds a fleet's keys (ca.key): pick an empty folder")
    names = ["localhost", "127.0.0.1", *hosts]
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", "ca.key", cwd=folder)
    _openssl("req", "-x509", "-new", "-key", "ca.key", "-subj", "/CN=beastbt fleet CA", "-days", str(days),
             "-sha256", "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             "-out", "ca.crt", cwd=folder)
    _leaf(folder, "station", names, days)
    stems = {f"robot-{n}": n for n in robots} or {"robot": "robot"}
    for stem, common_name in stems.items():
        _leaf(folder, stem, [], days, common_name)
    for key in ("ca.key", "station.key", *(f"{stem}.key" for stem in stems)):
        (folder / key).chmod(0o600)
    (folder / "ca.srl").unlink(missing_ok=True)
    connect = listen.replace("0.0.0.0", "127.0.0.1")
    (folder / "station.json5").write_text(json.dumps(station_json5(folder, listen, robots), indent=2) + "\n")
    for stem in stems:
        (folder / f"{stem}.json5").write_text(json.dumps(robot_json5(folder, connect, stem), indent=2) + "\n")
    (folder / "README.txt").write_text(HOWTO.format(folder=folder, hosts=", ".join(names)))
    return sorted(folder.iterdir())


__all__ = ["init_keys", "station_json5", "robot_json5", "ROBOT_INGRESS"]
