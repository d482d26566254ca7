"""The attachment rmw_zenoh sends with every sample: sequence number, source timestamp, publisher GID.

Followed: rmw_zenoh_cpp ``src/detail/attachment_helpers.cpp`` (``AttachmentData``, the zenoh 1.x code of Jazzy)
and ``docs/design.md`` (Publishers). It is zenoh-ext serialization of ``(int64 sequence_number, int64
source_timestamp, std::array<uint8_t, 16> gid)``: 8 + 8 bytes little endian, the GID's length as LEB128 (one
byte, 16), then the 16 bytes; 33 in all. Written here with zenoh's own serializer, not by hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import zenoh
from zenoh.ext import Int64, z_deserialize, z_serialize

GID_SIZE = 16  # RMW_GID_STORAGE_SIZE
#: The bytes of an attachment: two int64, the GID's length (one LEB128 byte) and the GID.
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE


@dataclass(frozen=True, slots=True)
class Attachment:
    """What rmw_zenoh attaches to every sample (``AttachmentData``); its subscribers drop a sample without one."""

    sequence_number: int
    source_timestamp: int  # ns since the epoch, the publisher's clock
    gid: bytes

    def encode(self) -> bytes:
        """``AttachmentData::serialize_to_zbytes``: 33 bytes."""
        if len(self.gid) != GID_SIZE:
            raise ValueError(f"a GID is {GID_SIZE} bytes, not {len(self.gid)}")
        return z_serialize((Int64(self.sequence_number), Int64(self.source_timestamp), self.gid)).to_bytes()

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """The inverse of :meth:`encode`; ValueError for bytes that are not an rmw_zenoh attachment.

        Bytes after the GID are ignored, as rmw_zenoh's ``AttachmentData(const zenoh::Bytes &)`` ignores them.
        """
        try:
            seq, stamp, gid = z_deserialize(tuple[Int64, Int64, bytes], zenoh.ZBytes(data))
        except Exception as exc:  # zenoh's ZDeserializeError: too short, a bad length
            raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes): {exc}") from exc
        if len(gid) != GID_SIZE:
            raise ValueError(f"not an rmw_zenoh attachment: a {len(gid)}-byte GID")
        return cls(int(seq), int(stamp), bytes(gid))
