"""zenoh-bridge-ros2dds's wire format: what a ROS 2 on DDS (Humble's default) sees through the bridge.

A laptop runs ``zenoh-bridge-ros2dds -e tcp/<robot>:7447``; the bridge routes
each ROS 2 topic between its DDS and Zenoh (eclipse-zenoh/zenoh-plugin-ros2dds 1.x, the bridges that speak
beastbt's Zenoh 1.x: ``liveliness_mgt.rs`` at commit 09d68c0, lines 26-37 and 186-232, followed here):

* **Data key**: the topic name without its leading '/', under the bridge's ``namespace`` when one is set
  (``scan``, or ``robot1/scan``); the payload is the message's CDR with its encapsulation header, as DDS
  sends it; no attachment.
* **Liveliness tokens** announce each publisher and subscription to the other bridges:
  ``@/<zid>/@ros2_lv/MP/<key>/<type>/<qos>`` (``MS`` for a subscription; the bridges before 1.0, on Zenoh
  0.11, wrote ``@ros2_lv/<zid>/MP/...``, and a bridge 1.x subscribes to ``@/*/@ros2_lv/**`` only), '/' in the
  key and the ROS type (``sensor_msgs/msg/LaserScan``) escaped to '§', and ``<qos>`` = ``<K if keyed>:<reliability>:
  <durability>:<history>,<depth>`` with DDS's enums (reliability 0 best effort, 1 reliable; durability 0
  volatile, 1 transient local; history 0 keep last, 1 keep all); the bridge itself holds
  ``@/<zid>/@ros2_lv``. ROS types are keyless: the first field is empty.
"""

from __future__ import annotations

from beastbt.ros2.rmw_zenoh import BEST_EFFORT, KEEP_ALL, TRANSIENT_LOCAL, Qos

ADMIN_SPACE = "@ros2_lv"
SLASH_REPLACEMENT = "§"


def data_key(topic: str, namespace: str = "/") -> str:
    """The key of ``topic`` (``/scan``) under the bridge's ``namespace`` (``/`` for none): ``scan``, ``ns/scan``."""
    ns = namespace.strip("/")
    name = topic.lstrip("/")
    return f"{ns}/{name}" if ns else name


def qos_keyexpr(qos: Qos) -> str:
    """The bridge's QoS chunk (``qos_to_key_expr``, keyless): ``:<reliability>:<durability>:<history>,<depth>``."""
    reliability = 0 if qos.reliability == BEST_EFFORT else 1
    durability = 1 if qos.durability == TRANSIENT_LOCAL else 0
    history = 1 if qos.history == KEEP_ALL else 0
    return f":{reliability}:{durability}:{history},{qos.depth}"


def escape(text: str) -> str:
    """'/' -> '§' (``escape_slashes``)."""
    return text.replace("/", SLASH_REPLACEMENT)


def plugin_token(zid: str) -> str:
    """The token that says a bridge (here: beastbt) is up: ``@/<zid>/@ros2_lv``."""
    return f"@/{zid}/{ADMIN_SPACE}"


def endpoint_token(zid: str, kind: str, key: str, type_name: str, qos: Qos) -> str:
    """A publisher's (``MP``) or subscription's (``MS``) token: ``@/<zid>/@ros2_lv/MP/<key>/<type>/<qos>``."""
    return f"@/{zid}/{ADMIN_SPACE}/{kind}/{escape(key)}/{escape(type_name)}/{qos_keyexpr(qos)}"


__all__ = ["data_key", "qos_keyexpr", "escape", "plugin_token", "endpoint_token"]
