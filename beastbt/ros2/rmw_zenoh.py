"""rmw_zenoh's wire format: topic keys, liveliness tokens, QoS strings and attachments, pinned to one version.

What a ROS 2 node on ``RMW_IMPLEMENTATION=rmw_zenoh_cpp`` expects of a peer,
as rmw_zenoh_cpp writes it in the version pinned in :data:`PINNED`
(docs/ros2.md cites the lines):

* **Data key** (``TopicInfo::TopicInfo``, liveliness_utils.cpp):
  ``<domain>/<topic without leading and trailing '/'>/<DDS type name>/<type hash>``, e.g.
  ``0/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c1...``. On Humble the type hash is
  ``TypeHashNotSupported``.
* **Payload**: the message's CDR with its 4-byte encapsulation header (:mod:`beastbt.ros2.cdr`).
* **Attachment** (``AttachmentData::serialize_to_zbytes``, attachment_helpers.cpp), written with zenoh's
  ``ext::Serializer``: the sequence number (int64, from 1), the source timestamp (int64, ns since the Unix
  epoch), then the 16-byte GID as zenoh serialises a ``std::array<uint8_t, 16>``: a sequence, its length as a
  LEB128 varint (one byte, 0x10) then the bytes. 33 bytes, little-endian.
* **Liveliness tokens** (``Entity::Entity``): ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/<kind>/<enclave>/
  <namespace>/<node>`` for a node (kind ``NN``), followed by ``/<topic>/<type>/<hash>/<qos>`` for a publisher
  (``MP``) or subscription (``MS``); '/' in the names is mangled to '%' (so the root namespace is ``%``).
  ``zid`` is the session's Zenoh id as text, ``nid`` and ``eid`` numbers unique in the session.
* **QoS string** (``qos_to_keyexpr``): ``reliability:durability:history,depth:deadline_s,deadline_ns:
  lifespan_s,lifespan_ns:liveliness,lease_s,lease_ns``, each field empty when it equals rmw_zenoh's default
  (qos.cpp: reliable, volatile, keep last 42, infinite durations, automatic liveliness); enum values are
  rmw's (reliability 1 reliable, 2 best effort; durability 1 transient local, 2 volatile; history 1 keep
  last, 2 keep all).
* **Transient local** publishers (``PublisherData::make``, rmw_publisher_data.cpp) are zenoh-ext
  ``AdvancedPublisher`` s with a cache of ``depth`` samples and publisher detection: a late subscriber
  (rviz2's map display) gets the last map from that cache.

* **GID** (``Entity::Entity``): the XXH3-128 (seed 0, the default secret) of the entity's whole token,
  its low 64 bits then its high 64 bits, each little-endian (``memcpy`` of ``low64`` then ``high64``);
  rmw_zenoh carries a subset of the reference xxHash for it (simplified_xxhash3.cpp @97aed481), beastbt the
  reference itself (the ``xxhash`` package). So the GID in each message's attachment is the one a laptop's
  graph cache computes from the publisher's token (``ros2 topic info -v``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Optional

from beastbt.ros2.cdr import TYPES

PINNED = ("rmw_zenoh_cpp 0.2 (ROS 2 Jazzy, zenoh-cpp 1.x): ros2/rmw_zenoh at commits 3411fdec (liveliness_utils.cpp), "
          "534747dc (attachment_helpers.cpp), 7efeee2b (qos.cpp), 3e19ec73 (rmw_publisher_data.cpp), "
          "97aed481 (simplified_xxhash3.cpp); Humble: pull request #388")
"""The rmw_zenoh this module follows (docs/ros2.md cites the lines)."""

ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT = "NN", "MP", "MS", "SS", "SC"
HASH_NOT_SUPPORTED = "TypeHashNotSupported"
"""The type hash rmw_zenoh on Humble puts in keys and tokens (Humble has no type hashes)."""

# rmw's QoS enums (rmw/types.h)
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
DEFAULT_DEPTH = 42
"""rmw_zenoh's default history depth (qos.cpp)."""


@dataclass(frozen=True)
class Qos:
    """The QoS of one publisher or subscription: ``reliability`` (:data:`RELIABLE`, :data:`BEST_EFFORT`),
    ``durability`` (:data:`VOLATILE`, :data:`TRANSIENT_LOCAL`), ``history`` and ``depth``. Deadline, lifespan
    and liveliness are rmw_zenoh's defaults (what rclcpp's profiles leave them at)."""

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10


SENSOR_DATA = Qos(BEST_EFFORT, VOLATILE, KEEP_LAST, 5)
"""rclcpp's ``SensorDataQoS`` (best effort, depth 5): what ROS drivers use for scans, images, IMU, GPS."""
DEFAULT = Qos(RELIABLE, VOLATILE, KEEP_LAST, 10)
"""rclcpp's default ``QoS(10)``: odometry, tf, plans, diagnostics, commands."""
LATCHED = Qos(RELIABLE, TRANSIENT_LOCAL, KEEP_LAST, 1)
"""Transient local, depth 1: the map (as map_server) and ``/tf_static``."""


def qos_keyexpr(qos: Qos) -> str:
    """The QoS part of a token (``qos_to_keyexpr``): each field empty when it is rmw_zenoh's default."""
    def field(value: int, default: int) -> str:
        return "" if value == default else str(value)
    return (f"{field(qos.reliability, RELIABLE)}:{field(qos.durability, VOLATILE)}:"
            f"{field(qos.history, KEEP_LAST)},{field(qos.depth, DEFAULT_DEPTH)}:,:,:,,")


def strip_slashes(name: str) -> str:
    """``/scan/`` -> ``scan`` (rmw_zenoh's ``strip_slashes``: one leading and one trailing '/')."""
    if name.startswith("/"):
        name = name[1:]
    if name.endswith("/"):
        name = name[:-1]
    return name


def mangle(name: str) -> str:
    """'/' -> '%' (rmw_zenoh's ``mangle_name``): a name as one chunk of a key expression."""
    return name.replace("/", "%")


def demangle(name: str) -> str:
    """'%' -> '/' (``demangle_name``)."""
    return name.replace("%", "/")


def type_hash(type_name: str, humble: bool = False) -> str:
    """The type hash rmw_zenoh puts in keys and tokens: ``RIHS01_<64 hex>``, or on Humble
    :data:`HASH_NOT_SUPPORTED`."""
    return HASH_NOT_SUPPORTED if humble else TYPES[type_name].rihs01


def topic_key(domain: int, topic: str, type_name: str, humble: bool = False) -> str:
    """The key a topic's messages are put on (``0/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_...``)."""
    return f"{int(domain)}/{strip_slashes(topic)}/{TYPES[type_name].dds_name}/{type_hash(type_name, humble)}"


@dataclass(frozen=True)
class Node:
    """A ROS 2 node as rmw_zenoh announces it: domain, the session's Zenoh id, node id, namespace, name, enclave."""

    domain: int
    zid: str
    nid: int
    namespace: str = "/"
    name: str = "beastbt"
    enclave: str = "/"

    def token(self, eid: Optional[int] = None) -> str:
        """The node's liveliness token (``NN``); its entity id is its node id unless given."""
        return self._prefix(self.nid if eid is None else eid, NODE)

    def _prefix(self, eid: int, kind: str) -> str:
        return (f"{ADMIN_SPACE}/{int(self.domain)}/{self.zid}/{self.nid}/{eid}/{kind}/{mangle(self.enclave)}/"
                f"{mangle(self.namespace)}/{mangle(self.name)}")

    def endpoint_token(self, eid: int, kind: str, topic: str, type_name: str, qos: Qos, humble: bool = False) -> str:
        """The token of a publisher (``MP``) or subscription (``MS``) of ``topic`` (a full name, ``/scan``)."""
        return (f"{self._prefix(eid, kind)}/{mangle(topic)}/{mangle(TYPES[type_name].dds_name)}/"
                f"{mangle(type_hash(type_name, humble))}/{qos_keyexpr(qos)}")


def gid(token: str) -> bytes:
    """The 16-byte GID of the entity with liveliness ``token``: rmw_zenoh's XXH3-128 of it, low half first, each
    half little-endian (see the module docstring)."""
    import xxhash
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")


_ATTACHMENT = struct.Struct("<qqB16s")


def attachment(sequence_number: int, source_timestamp_ns: int, source_gid: bytes) -> bytes:
    """The attachment of one message: int64 sequence number, int64 timestamp (ns), the GID as a 16-long sequence."""
    if len(source_gid) != 16:
        raise ValueError(f"a GID is 16 bytes, not {len(source_gid)}")
    return _ATTACHMENT.pack(int(sequence_number), int(source_timestamp_ns), 16, bytes(source_gid))


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, GID) of an attachment; ValueError when it is not one."""
    if len(data) != _ATTACHMENT.size:
        raise ValueError(f"an rmw_zenoh attachment is {_ATTACHMENT.size} bytes, not {len(data)}")
    seq, ts, n, g = _ATTACHMENT.unpack(data)
    if n != 16:
        raise ValueError(f"the GID's length is {n}, not 16")
    return seq, ts, g


__all__ = ["PINNED", "Qos", "Node", "SENSOR_DATA", "DEFAULT", "LATCHED", "qos_keyexpr", "topic_key", "type_hash",
           "mangle", "demangle", "strip_slashes", "gid", "attachment", "parse_attachment", "PUBLISHER",
           "SUBSCRIPTION", "NODE", "HASH_NOT_SUPPORTED", "RELIABLE", "BEST_EFFORT", "VOLATILE", "TRANSIENT_LOCAL",
           "KEEP_LAST", "KEEP_ALL"]
