"""Pigweed: pw_rpc packets in pw_hdlc frames, from the PyPI ``pigweed`` package.

``pigweed`` is installed without its dependencies (tools/bench_setup.sh): it declares about
fifty of them (Sphinx, pylint, cloud storage, ``protobuf~=5.28``) that pw_hdlc and pw_rpc's
packet code do not import. One consequence, measured with pigweed 0.0.24 and protobuf 7: the
callback client (``pw_rpc.callback_client``) fails while building method signatures
(``FieldDescriptor.label`` is gone from protobuf 7), so the request and response bytes come
from ``pw_rpc.packets.encode_request`` / ``encode_response``, the functions that client calls
to make its packets, wrapped by ``pw_hdlc.encode.ui_frame`` as ``pw_hdlc.rpc`` does.
"""

from __future__ import annotations

import functools
import importlib.util
import random
import tempfile
from pathlib import Path
from typing import Any

from ..core import require
from . import RxCase, Slot, WireSample, chunked

PROTO = Path(__file__).resolve().parents[1] / "proto" / "servo_rpc.proto"
SERVICE = "protoduino.bench.Servo"

#: pw_hdlc.rpc's defaults: channel 1 on HDLC address ord('R').
CHANNEL_ID = 1
RPC_ADDRESS = ord("R")


@functools.cache
def servo_rpc_module() -> Any:
    """bench/proto/servo_rpc.proto compiled with grpc_tools and imported (once per process)."""
    protoc = require("grpc_tools.protoc", "grpcio-tools")
    with tempfile.TemporaryDirectory(prefix="protoduino-bench-") as out:
        args = ["protoc", f"-I{PROTO.parent}", f"--python_out={out}", str(PROTO)]
        if protoc.main(args) != 0:
            raise RuntimeError(f"grpc_tools.protoc failed on {PROTO}")
        generated = Path(out, "servo_rpc_pb2.py")
        spec = importlib.util.spec_from_file_location("servo_rpc_pb2", generated)
        if spec is None or spec.loader is None:
            raise RuntimeError("cannot load the compiled servo_rpc_pb2")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    return module


class _Pigweed:
    """The pieces of pigweed the benchmarks use, imported together."""

    def __init__(self) -> None:
        self.decode = require("pw_hdlc.decode", "pigweed")
        self.encode = require("pw_hdlc.encode", "pigweed")
        self.packets = require("pw_rpc.packets", "pigweed")
        self.descriptors = require("pw_rpc.descriptors", "pigweed")
        self.pb = servo_rpc_module()
        service = self.descriptors.Service.from_descriptor(
            self.pb.DESCRIPTOR.services_by_name["Servo"]
        )
        self.service_id: int = service.id
        self.method_id: int = service.methods["SetAngle"].id

    def ids(self, call_id: int) -> Any:
        return self.descriptors.RpcIds(CHANNEL_ID, self.service_id, self.method_id, call_id)

    def request_frame(self, call_id: int, pin: int, degrees: int) -> bytes:
        request = self.pb.SetAngleRequest(pin=pin, degrees=degrees)
        packet = self.packets.encode_request(self.ids(call_id), request)
        return bytes(self.encode.ui_frame(RPC_ADDRESS, packet))

    def response_frame(self, call_id: int) -> bytes:
        packet = self.packets.encode_response(self.ids(call_id), self.pb.SetAngleResponse())
        return bytes(self.encode.ui_frame(RPC_ADDRESS, packet))


def rx_case(frames: int, chunk: int, seed: int) -> RxCase:
    """SetAngle responses, as a host receives them, through FrameDecoder and RpcPacket."""
    pw = _Pigweed()
    rng = random.Random(seed)
    first = rng.randrange(1, 1 << 20)
    call_ids = [first + i for i in range(frames)]
    stream = b"".join(pw.response_frame(call_id) for call_id in call_ids)
    chunks = chunked(stream, chunk)
    pending = {(CHANNEL_ID, pw.service_id, pw.method_id, call_id): Slot() for call_id in call_ids}
    decode_packet = pw.packets.decode
    decode_payload = pw.packets.decode_payload
    response_type = pw.pb.SetAngleResponse

    def run() -> int:
        decoder = pw.decode.FrameDecoder()
        handled = 0
        for data in chunks:
            for frame in decoder.process(data):
                if not frame.ok() or frame.address != RPC_ADDRESS:
                    continue
                packet = decode_packet(frame.data)
                key = (packet.channel_id, packet.service_id, packet.method_id, packet.call_id)
                waiter = pending.get(key)
                if waiter is not None:
                    waiter.value = decode_payload(packet, response_type)
                    handled += 1
        return handled

    return RxCase(
        name="Pigweed pw_hdlc + pw_rpc",
        package="pigweed",
        parser="pure Python, byte by byte (FrameDecoder.process_byte); CRC-32 from zlib; "
        "RpcPacket with the installed protobuf (upb)",
        stages="FrameDecoder.process -> Frame -> pw_rpc.packets.decode (RpcPacket) -> "
        "pending call by (channel, service, method, call id) -> response payload decoded "
        "(the same stand-in as protoduino's: pw_rpc's own client cannot be built on protobuf "
        "7, see bench/peers/pigweed.py)",
        stream=stream,
        frames=frames,
        run=run,
    )


def wire_sample() -> WireSample:
    pw = _Pigweed()
    # The Python client's first call id is 1; the device answers on the same ids.
    return WireSample(
        library="pw_rpc over HDLC",
        package="pigweed",
        encoder="pw_rpc.packets.encode_request / encode_response + pw_hdlc.encode.ui_frame",
        setup=None,
        setup_what="none in pw_rpc itself; a servo service would define its own",
        command=pw.request_frame(1, 9, 90),
        command_what="REQUEST Servo.SetAngle{pin 9, degrees 90} (bench/proto/servo_rpc.proto)",
        ack=pw.response_frame(1),
        ack_what="RESPONSE status OK, empty SetAngleResponse",
        check="CRC-32",
        notes="service and method ids are 32-bit name hashes (fixed32); HDLC frames carry a "
        "CRC-32 and 0x7E flags, with 0x7D escapes",
    )
