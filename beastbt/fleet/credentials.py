"""``beastbt station --init-keys DIR``: a fleet's own CA, the station's and the robots' certificates, two Zenoh configs.

Written with the ``openssl`` command (no Python dependency for a job done
once): ``ca.crt``/``ca.key`` (the fleet's certificate authority; keep
``ca.key`` off the robots), ``station.crt``/``.key`` (common name
``station``, valid for ``localhost``, ``127.0.0.1`` and each ``--host``),
``robot.crt``/``.key`` (common name ``robot``, for every robot), and
``station.json5`` and ``robot.json5``: standard Zenoh configurations for
mutual TLS (each side proves itself with a certificate of this CA; no other
transport is accepted) with Zenoh's access control on the router: a robot
may publish its state, events and newest photo, declare its liveliness token and its
queryables, answer queries, hear the stop-all and the simulated robots' poses the station relays, and
nothing else; only the
station queries (commands, missions) and puts the stop-all. ``README.txt``
says how to use them.

Each robot's **enrolment** is a folder of its own, ``robot/`` (or
``robot-NAME/`` with ``--robot-name``): ``ca.crt``, ``robot.crt``,
``robot.key`` and ``robot.json5`` (which names them relative to itself), all
a robot needs to join and nothing more (never ``ca.key``). Copied to a
robot's fleet folder (:func:`~beastbt.fleet.config.fleet_folder`), it is
found by ``beastbt serve --fleet tls/STATION:7447`` without
``--fleet-config``. :func:`ensure_keys` is ``beastbt station``'s first start:
the keys made once in the per-user fleet folder, and the station's
certificate made again (same CA: the robots keep theirs) when the station is
reached by a new name.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import NamedTuple, Sequence

VALID_DAYS = 3650
"""How long the certificates are valid (days): a classroom's robots outlive a year."""
ROBOT_INGRESS = [
    (["put"], ["beastbt/*/state", "beastbt/*/events", "beastbt/*/photo"]),
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


def station_json5(folder: Path, listen: str, robots: Sequence[str] = (), shared: bool = False) -> dict:
    """The station's Zenoh configuration (a router, mutual TLS only, access control for robots).

    Without ``robots`` every robot has the common name ``robot`` and may use any robot's keys; with them,
    each robot has its own certificate (common name: its name) and may use its own keys only (and, with
    ``shared``, the robots with the common certificate ``robot`` too, as without ``robots``).
    """
    groups = [(f"robot-{n}", n, _robot_rules(f"robot-{n}", n)) for n in robots]
    if shared or not groups:
        groups.append(("robots", "robot", _robot_rules("robot", "*")))
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


def robot_json5(folder: Path, connect: str, stem: str = "robot", relative: bool = False) -> dict:
    """A robot's Zenoh configuration (a peer connecting to the station by mutual TLS only), with the key and
    certificate ``stem.key``, ``stem.crt`` in ``folder`` (``relative``: named relative to the configuration's own
    folder, as an enrolment is, which beastbt finds beside the file)."""
    from beastbt.fleet.config import OPEN_TIMEOUT_MS, RETRY
    if relative:
        folder = Path()
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


HOWTO = """The fleet's keys (beastbt station --init-keys, or the first start of beastbt station), and how to use them.

On the station:
    beastbt station --fleet-config {folder}/station.json5 --listen tls/0.0.0.0:7447
On each robot, its enrolment: copy the folder {folder}/robot/ (with --robot-name NAME, robot-NAME/, each to its
own robot) to the robot, into ~/.local/state/beastbt/fleet/ (then --fleet-config is not needed), e.g.
    ssh ROBOT mkdir -p .local/state/beastbt/fleet && scp {folder}/robot/* ROBOT:.local/state/beastbt/fleet/
and run there:
    beastbt serve --robot PROFILE --fleet tls/STATION:7447 [--name NAME]
(or, with the folder anywhere: --fleet-config FOLDER/robot.json5; its files are found beside it).

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
    names = list(dict.fromkeys(["localhost", "127.0.0.1", *hosts]))
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
        _enrolment(folder, stem, connect)
    (folder / "README.txt").write_text(HOWTO.format(folder=folder, hosts=", ".join(names)))
    return sorted(folder.iterdir())


def _enrolment(folder: Path, stem: str, connect: str) -> Path:
    """The folder ``folder/stem/``: what robot ``stem`` needs to join (the CA's certificate, its key and certificate,
    its configuration naming them relative to itself), and nothing else."""
    out = folder / stem
    out.mkdir(exist_ok=True)
    out.chmod(0o700)
    shutil.copyfile(folder / "ca.crt", out / "ca.crt")
    shutil.copyfile(folder / f"{stem}.crt", out / "robot.crt")
    key = out / "robot.key"
    key.write_bytes((folder / f"{stem}.key").read_bytes())
    key.chmod(0o600)
    (out / "robot.json5").write_text(json.dumps(robot_json5(out, connect, "robot", relative=True), indent=2) + "\n")
    return out


def enrolments(folder: Path) -> list[Path]:
    """The robots' enrolment folders in ``folder`` (``robot/``, ``robot-NAME/``), by name."""
    return sorted(p for p in folder.glob("robot*") if p.is_dir() and (p / "robot.json5").is_file())


def station_names(folder: Path) -> list[str]:
    """The names and addresses the station's certificate in ``folder`` is valid for."""
    out = subprocess.run(["openssl", "x509", "-in", str(folder / "station.crt"), "-noout", "-ext", "subjectAltName"],
                         check=True, capture_output=True, text=True).stdout
    return re.findall(r"(?:DNS|IP Address):([^,\s]+)", out)


class KeysState(NamedTuple):
    """What :func:`ensure_keys` did: whether the keys were made now, the names added to the station's certificate,
    the robots given a certificate of their own."""

    made: bool
    hosts_added: list
    robots_added: list


def ensure_keys(folder: Path, hosts: Sequence[str], listen: str, robots: Sequence[str] = ()) -> KeysState:
    """The keys of ``beastbt station`` in ``folder``: made when it holds none (:func:`init_keys`). When it does:
    a name of ``hosts`` the station's certificate is not valid for makes that certificate again with every name
    (signed by the same CA: the robots' enrolments stay good), and a robot of ``robots`` without a certificate of
    its own gets one, with its enrolment (``robot-NAME/``), and the station's access control is written again.

    ``FileExistsError`` when ``folder`` holds something else than a station's keys (a robot's enrolment).
    """
    folder = folder.resolve()
    if not (folder / "ca.key").is_file():
        if folder.is_dir() and any(folder.iterdir()):
            raise FileExistsError(f"{folder} holds no fleet CA (ca.key) but other files (a robot's enrolment?): "
                                  f"give the station a folder of its own with --keys DIR")
        init_keys(folder, hosts, listen, robots=robots)
        folder.chmod(0o700)  # the CA's key: this user's only
        return KeysState(True, [], [])
    names = station_names(folder)
    added = [h for h in dict.fromkeys(hosts) if h not in names]
    if added:
        _leaf(folder, "station", [*names, *added], VALID_DAYS)
        (folder / "station.key").chmod(0o600)
    new_robots = [r for r in dict.fromkeys(robots) if not (folder / f"robot-{r}.crt").is_file()]
    connect = listen.replace("0.0.0.0", "127.0.0.1")
    for name in new_robots:  # enrolled later: a certificate of its own, signed by the same CA
        stem = f"robot-{name}"
        _leaf(folder, stem, [], VALID_DAYS, name)
        (folder / f"{stem}.key").chmod(0o600)
        (folder / f"{stem}.json5").write_text(json.dumps(robot_json5(folder, connect, stem), indent=2) + "\n")
        _enrolment(folder, stem, connect)
    if new_robots:
        named = sorted(p.name[len("robot-"):-len(".crt")] for p in folder.glob("robot-*.crt"))
        config = station_json5(folder, listen, named, shared=(folder / "robot.crt").is_file())
        (folder / "station.json5").write_text(json.dumps(config, indent=2) + "\n")
    (folder / "ca.srl").unlink(missing_ok=True)
    return KeysState(False, added, new_robots)


__all__ = ["init_keys", "ensure_keys", "KeysState", "station_names", "enrolments", "station_json5", "robot_json5",
           "ROBOT_INGRESS"]
