#!/usr/bin/env python3
"""Writes the seed recordings of fuzz_record (tests/fuzz/README.md) from the fuzz_idl seeds.

    build/bin/fuzz_idl_seeds /tmp/idl && tests/fuzz/seeds/make_recording_seed.py /tmp/idl tests/fuzz/seeds

recording.rfx: the file header, then one record of every topic type (topic, DDS type name, a
serialized sample as fuzz_idl_seeds writes it) twice, 10 ms apart, in the layout of
modules/record/include/reflex/record/record_file.hpp. recording_torn.rfx: the same file cut inside
its last record (what a kill -9 leaves). No recording is shipped in bringup/, hence these.
"""
import struct
import sys
import zlib
from pathlib import Path

# fuzz_idl selector byte -> (default topic, DDS type name); order of idl_seeds.cpp / fuzz_idl.cpp.
TYPES = [
    ("reflex/object_targets", "reflex::msg::ObjectTargets"),
    ("reflex/hand_targets", "reflex::msg::HandTargets"),
    ("reflex/motion_priority", "reflex::msg::MotionPriority"),
    ("reflex/body_schema", "reflex::msg::BodySchemaChange"),
    ("reflex/walk_command", "reflex::msg::WalkCommand"),
    ("reflex/joint_state", "reflex::msg::JointState"),
    ("reflex/control_status", "reflex::msg::ControlStatus"),
    ("reflex/heartbeat", "reflex::msg::Heartbeat"),
]
SYNC = 0x43455252  # "RREC"


def record(receive_ns, source_ns, topic, type_name, payload):
    body = struct.pack("<qq", receive_ns, source_ns)
    body += struct.pack("<H", len(topic)) + topic.encode()
    body += struct.pack("<H", len(type_name)) + type_name.encode()
    body += struct.pack("<I", len(payload)) + payload
    return struct.pack("<III", SYNC, len(body), zlib.crc32(body) & 0xFFFFFFFF) + body


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: make_recording_seed.py IDL_SEED_DIR OUT_DIR")
    seeds, out = Path(sys.argv[1]), Path(sys.argv[2])
    data = b"RFXREC\r\n" + struct.pack("<II", 1, 0)
    t = 1_700_000_000_000_000_000
    for rep in range(2):
        for selector, (topic, type_name) in enumerate(TYPES):
            payload = (seeds / f"seed_{selector}").read_bytes()[1:]  # byte 0 is fuzz_idl's selector
            data += record(t, t - 1_000_000, topic, type_name, payload)
            t += 10_000_000
    (out / "recording.rfx").write_bytes(data)
    (out / "recording_torn.rfx").write_bytes(data[:-7])


if __name__ == "__main__":
    main()
