"""rmw_zenoh's and zenoh-bridge-ros2dds's keys, liveliness tokens and attachments, golden strings and bytes.

Each golden value below is derived by hand from the pinned sources (beastbt/ros2/rmw_zenoh.py: PINNED), the
line it follows cited beside it:

- ros2/rmw_zenoh rmw_zenoh_cpp/src/detail/liveliness_utils.cpp @3411fdec: ``TopicInfo::TopicInfo`` (the data
  key: domain, strip_slashes(name), type, hash joined by '/'), ``Entity::Entity`` (the token's parts
  AdminSpace/DomainId/Zid/Nid/Id/EntityStr/Enclave/Namespace/NodeName[/TopicName/TopicType/TopicTypeHash/
  TopicQoS], each name through ``mangle_name``), ``qos_to_keyexpr`` (empty where the value is the default);
- rmw_zenoh_cpp/src/detail/qos.cpp @7efeee2b: the defaults (reliable, volatile, keep last 42);
- rmw_zenoh_cpp/src/detail/attachment_helpers.cpp @534747dc: ``serialize_to_zbytes`` (int64, int64,
  std::array<uint8_t, 16> through zenoh's ext::Serializer), checked here against zenoh's own serializer;
- eclipse-zenoh/zenoh-plugin-ros2dds zenoh-plugin-ros2dds/src/liveliness_mgt.rs @49cf1bcb: ``ke_liveliness_pub``
  and ``qos_to_key_expr`` (its own unit test gives ``:::`` for a keyless default QoS);
- liveliness_utils.cpp @3411fdec ``Entity::Entity``, the GID: ``simplified_XXH3_128bits`` of the whole token
  (simplified_xxhash3.cpp @97aed481, a subset of the reference xxHash 0.8), then ``memcpy`` of ``low64`` and
  ``high64`` into the 16 bytes. The golden GIDs were computed twice, agreeing: by that file's 17-128 and
  129-240 byte paths transcribed by hand (a one-off check, with 300 random inputs), and by the reference xxHash;
- the Humble branch (ros2/rmw_zenoh pull request #388, "Updates to compile against Humble"): no type hashes,
  "set it to a constant string" ``TypeHashNotSupported``, in the data key and the token alike; the GID stays
  16 bytes (``RMW_GID_STORAGE_SIZE`` hard-coded to 16), so the attachment is the same.
"""

from __future__ import annotations

import pytest

from beastbt.ros2 import bridge, rmw_zenoh as rz

ZID = "8fe2c4a1b37d9e0f11223344556677aa"
SCAN_HASH = "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"


def test_data_keys():
    assert rz.topic_key(0, "/scan", "sensor_msgs/msg/LaserScan") == f"0/scan/sensor_msgs::msg::dds_::LaserScan_/{SCAN_HASH}"
    assert (rz.topic_key(7, "/robot1/cmd_vel/", "geometry_msgs/msg/Twist") ==
            "7/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
            "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
    assert (rz.topic_key(0, "/scan", "sensor_msgs/msg/LaserScan", humble=True) ==
            "0/scan/sensor_msgs::msg::dds_::LaserScan_/TypeHashNotSupported")


@pytest.mark.parametrize("qos, text", [
    (rz.SENSOR_DATA, "2::,5:,:,:,,"),       # best effort (2) differs; volatile, keep last are defaults; depth 5
    (rz.DEFAULT, "::,10:,:,:,,"),           # reliable volatile keep-last: only the depth differs from 42
    (rz.LATCHED, ":1:,1:,:,:,,"),           # transient local (1), depth 1
    (rz.Qos(depth=42), "::,:,:,:,,"),       # every field the default: only the delimiters
    (rz.Qos(history=rz.KEEP_ALL, depth=42), "::2,:,:,:,,"),
])
def test_qos_strings(qos, text):
    assert rz.qos_keyexpr(qos) == text


def test_node_and_endpoint_tokens():
    node = rz.Node(0, ZID, 0, "/", "beastbt", "/")
    assert node.token() == f"@ros2_lv/0/{ZID}/0/0/NN/%/%/beastbt"
    assert (node.endpoint_token(3, rz.PUBLISHER, "/scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA) ==
            f"@ros2_lv/0/{ZID}/0/3/MP/%/%/beastbt/%scan/sensor_msgs::msg::dds_::LaserScan_/{SCAN_HASH}/2::,5:,:,:,,")
    ns = rz.Node(2, ZID, 1, "/robots/r1", "beastbt", "/")
    assert (ns.endpoint_token(5, rz.SUBSCRIPTION, "/robots/r1/cmd_vel", "geometry_msgs/msg/Twist", rz.DEFAULT,
                              humble=True) ==
            f"@ros2_lv/2/{ZID}/1/5/MS/%/%robots%r1/beastbt/%robots%r1%cmd_vel/geometry_msgs::msg::dds_::Twist_/"
            "TypeHashNotSupported/::,10:,:,:,,")


def test_tokens_and_keys_are_zenoh_key_expressions():
    zenoh = pytest.importorskip("zenoh")
    node = rz.Node(0, ZID, 0)
    for text in (node.token(), node.endpoint_token(1, rz.PUBLISHER, "/map", "nav_msgs/msg/OccupancyGrid", rz.LATCHED),
                 rz.topic_key(0, "/map", "nav_msgs/msg/OccupancyGrid"),
                 bridge.endpoint_token(ZID, "MP", "scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA)):
        assert str(zenoh.KeyExpr(text)) == text


def test_gid_is_rmw_zenohs_xxh3_of_the_token_low_half_first():
    node = rz.Node(0, ZID, 0)
    scan = node.endpoint_token(3, rz.PUBLISHER, "/scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA)
    assert len(scan) == 188 and len(node.token()) == 62  # XXH3's 129-240 and 17-128 byte paths
    assert rz.gid(scan) == bytes.fromhex("97c3f0ab2ecc6502924c7595acefacec")
    assert rz.gid(node.token()) == bytes.fromhex("e97c8b901ecc7a80bd4fe5d5f5c6a047")
    xxhash = pytest.importorskip("xxhash")
    digest = xxhash.xxh3_128_digest(scan.encode())  # canonical: high64 then low64, big-endian
    assert rz.gid(scan) == digest[8:][::-1] + digest[:8][::-1]  # memcpy(low64), memcpy(high64) on little-endian


def test_attachment_golden_bytes():
    gid = bytes(range(16))
    data = rz.attachment(7, 1_733_520_000_123_456_789, gid)
    assert data.hex() == ("0700000000000000"            # int64 sequence number 7, little-endian
                          "15cd646a41b30e18"            # int64 source timestamp (ns)
                          "10"                          # the GID's sequence length, LEB128: 16
                          "000102030405060708090a0b0c0d0e0f")
    assert rz.parse_attachment(data) == (7, 1_733_520_000_123_456_789, gid)


def test_attachment_is_what_zenohs_own_serializer_writes():
    ext = pytest.importorskip("zenoh.ext")
    gid = rz.gid("@ros2_lv/0/x/0/1/MP/%/%/beastbt/%odom/t/h/::,10:,:,:,,")
    ours = rz.attachment(123456, 42, gid)
    # zenoh-cpp's Serializer is zenoh-c's ze_serializer, the Rust zenoh-ext serializer Python's z_serialize uses:
    # a std::array<uint8_t, 16> goes as a sequence of 16 bytes, as Python bytes do.
    theirs = ext.z_serialize((ext.Int64(123456), ext.Int64(42), gid)).to_bytes()
    assert ours == theirs


@pytest.mark.parametrize("bad", [b"", bytes(32), bytes(16) + b"\x0f" + bytes(16)])
def test_bad_attachments_are_refused(bad):
    with pytest.raises(ValueError):
        rz.parse_attachment(bad)


def test_names_are_mangled_both_ways():
    assert rz.mangle("/a/b") == "%a%b" and rz.demangle("%a%b") == "/a/b"
    assert rz.strip_slashes("/scan/") == "scan" and rz.strip_slashes("scan") == "scan"


def test_bridge_keys_and_tokens():
    assert bridge.data_key("/scan") == "scan"
    assert bridge.data_key("/scan", "/robot1") == "robot1/scan"
    assert bridge.data_key("/camera/image/compressed") == "camera/image/compressed"
    assert bridge.plugin_token(ZID) == f"@/{ZID}/@ros2_lv"  # liveliness_mgt.rs:31 @09d68c0
    assert (bridge.endpoint_token(ZID, "MP", "scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA) ==
            f"@/{ZID}/@ros2_lv/MP/scan/sensor_msgs§msg§LaserScan/:0:0:0,5")
    assert (bridge.endpoint_token(ZID, "MP", "robot1/map", "nav_msgs/msg/OccupancyGrid", rz.LATCHED) ==
            f"@/{ZID}/@ros2_lv/MP/robot1§map/nav_msgs§msg§OccupancyGrid/:1:1:0,1")
    assert (bridge.endpoint_token(ZID, "MS", "cmd_vel", "geometry_msgs/msg/Twist", rz.DEFAULT) ==
            f"@/{ZID}/@ros2_lv/MS/cmd_vel/geometry_msgs§msg§Twist/:1:0:0,10")
