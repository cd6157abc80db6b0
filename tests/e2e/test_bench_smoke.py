"""Smoke tests of the benchmarks in bench/: every case runs on a few frames and its output is
checked (frames dispatched, bytes that decode back). Nothing here asserts on time.

A case whose library is not installed is skipped with the package's name; tools/bench_setup.sh
installs them all. The protoduino cases and the report generator need only the dev extras (and,
for the C accelerator's rows, a build of protoduino._speedups). Parts 2, 3 and 5 run against the
simulated board and the emulated Uno with a handful of calls; the emulator's counters are checked
exactly (bytes) or against each other (cycles), never against a clock.
"""

from __future__ import annotations

import dataclasses
import random
import re
import shutil
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # bench/ is a top-level folder of the checkout, not installed
    sys.path.insert(0, str(ROOT))

from protoduino import framing  # noqa: E402
from protoduino._generated import protoduino_pb2 as pb  # noqa: E402
from protoduino.constants import PacketType  # noqa: E402
from protoduino.errors import CommandRejectedError  # noqa: E402
from protoduino.framing import PyStreamDecoder, StreamDecoder  # noqa: E402
from protoduino.messages import parse_out  # noqa: E402
from protoduino.packets import Packet  # noqa: E402

from bench import boards, firmware, receive, roundtrip, runner, throughput, wire  # noqa: E402
from bench.core import MissingDependencyError, Timing, measure, require  # noqa: E402
from bench.peers import RxCase, Slot, WireSample, mavlink, pigweed, protoduino, serialtransfer  # noqa: E402
from bench.peers import firmata as firmata_peer  # noqa: E402
from bench.peers import telemetrix as telemetrix_peer  # noqa: E402

FRAMES = 60
CHUNK = 37  # odd, so that frames straddle reads
SEED = 3


T = TypeVar("T")


def _or_skip(make: Callable[[], T]) -> T:
    try:
        return make()
    except MissingDependencyError as missing:
        pytest.skip(f"{missing.package} not installed (tools/bench_setup.sh)")


def _small(factory: Callable[[int, int, int], RxCase]) -> Callable[[], RxCase]:
    return lambda: factory(FRAMES, CHUNK, SEED)


def _framing_only(decoder: Callable[[], protoduino.Decoder]) -> Callable[[], RxCase]:
    return lambda: protoduino.framing_only_case(FRAMES, CHUNK, SEED, decoder=decoder)


RX_FACTORIES: dict[str, Callable[[], RxCase]] = {
    **{label: _small(factory) for label, factory in receive.PEERS},
    **{f"{label} framing only": _framing_only(decoder) for label, decoder in protoduino.DECODERS},
    "DATA payload parsing": lambda: protoduino.payload_case(FRAMES, CHUNK, SEED, control=False),
    "CONTROL payload parsing": lambda: protoduino.payload_case(FRAMES, CHUNK, SEED, control=True),
}


def test_both_protoduino_decoders_are_measured_when_built() -> None:
    labels = [label for label, _decoder in protoduino.DECODERS]
    assert labels[-1] == "protoduino (pure Python)"
    assert ("protoduino (C accelerator)" in labels) == framing.ACCELERATED
    assert [label for label, _factory in receive.PEERS][: len(labels)] == labels


@pytest.mark.parametrize("name", sorted(RX_FACTORIES))
def test_receive_case_dispatches_every_frame(name: str) -> None:
    case = _or_skip(RX_FACTORIES[name])
    assert case.frames == FRAMES
    assert case.stream
    # Twice: each run must start from a fresh parser state.
    assert case.run() == FRAMES
    assert case.run() == FRAMES


def test_run_case_reports_rates_from_cpu_time() -> None:
    result = receive.run_case(protoduino.rx_case(FRAMES, CHUNK, SEED), reps=2)
    assert len(result.timing.samples) == 2
    assert result.frames_per_s > 0
    assert result.bytes_per_s == pytest.approx(result.frames_per_s * result.frame_size)


def test_run_case_refuses_a_case_that_loses_frames() -> None:
    good = protoduino.rx_case(FRAMES, CHUNK, SEED)
    lossy = dataclasses.replace(good, run=lambda: 1)
    with pytest.raises(RuntimeError, match="dispatched 1 of"):
        receive.run_case(lossy, reps=1)


def test_measure_times_each_repetition() -> None:
    calls: list[int] = []
    timing = measure(lambda: calls.append(1), reps=3, warmup=2)
    assert len(calls) == 5
    assert len(timing.samples) == 3
    assert all(s > 0 for s in timing.samples)


def test_protoduino_stream_resolves_every_ack() -> None:
    stream, ids = protoduino.mixed_stream(200, SEED)
    pending = {i: Slot() for i in ids}
    layer = protoduino.StandInRequestLayer(pending)
    layer.on_items(StreamDecoder().feed(stream))
    assert layer.dispatched == 200
    assert layer.lost == 0
    assert layer.bad == 0
    assert all(isinstance(slot.value, pb.Ack) for slot in pending.values())
    assert layer.events > 0  # the mix has failsafe and log events


def _damaged(stream: bytes, rng: random.Random) -> bytes:
    """Bit flips, insertions (long runs overflow), deletions and stray delimiters."""
    data = bytearray(stream)
    for _ in range(120):
        i = rng.randrange(len(data))
        op = rng.random()
        if op < 0.3:
            data[i] ^= 1 << rng.randrange(8)
        elif op < 0.5:
            data[i:i] = bytes(rng.randrange(1, 256) for _ in range(rng.randrange(1, 600)))
        elif op < 0.7:
            del data[i : i + rng.randrange(1, 20)]
        else:
            data[i:i] = b"\x00"
    return bytes(data)


@pytest.mark.skipif(
    not framing.ACCELERATED,
    reason="protoduino._speedups not built (needs a C compiler and python3-dev)",
)
@pytest.mark.parametrize("seed", range(4))
def test_both_decoders_agree_on_a_damaged_bench_stream(seed: int) -> None:
    """The two protoduino rows of the report decode the same stream to the same items;
    tests/unit/test_framing_props.py holds both to the recovery policy in detail."""
    rng = random.Random(seed)
    stream, _ids = protoduino.mixed_stream(600, seed)
    data = _damaged(stream, rng)
    for _ in range(5):
        cuts = sorted(rng.sample(range(1, len(data)), rng.randrange(1, 300)))
        chunks = [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]
        ref, new = PyStreamDecoder(), StreamDecoder()
        expected = [item for chunk in chunks for item in ref.feed(chunk)]
        got = [item for chunk in chunks for item in new.feed(chunk)]
        assert [(type(i), *i) for i in got] == [(type(i), *i) for i in expected]
        assert new.counts == ref.counts
    # The damage must have exercised every drop reason, or the comparison proves little.
    assert {"cobs", "crc", "overflow", "packets"} <= set(ref.counts)


# --- part 4: the bytes decode back with each library's own decoder -----------------------


def _sample(make: Callable[[], WireSample]) -> WireSample:
    return _or_skip(make)


def test_protoduino_wire_sample_decodes() -> None:
    s = _sample(protoduino.wire_sample)
    assert s.setup is not None and s.ack is not None
    dec = StreamDecoder()
    command, ack = dec.feed(s.command), dec.feed(s.ack)
    assert len(command) == 1 and isinstance(command[0], Packet)
    assert len(ack) == 1 and isinstance(ack[0], Packet)
    assert command[0].type is PacketType.COMMAND and ack[0].type is PacketType.DATA
    msg = pb.ArduinoIn.FromString(command[0].payload)
    assert (msg.servo_control.pin, msg.servo_control.degrees) == (9, 90)
    assert ack[0].payload[0] == 0x38  # the short Ack (ArduinoOut.ack_ok, protocol version 5)
    reply = parse_out(ack[0].payload)
    assert reply.ack.message_id == msg.message_id
    assert reply.ack.status == pb.STATUS_OK


def test_mavlink_wire_sample_decodes() -> None:
    s = _sample(mavlink.wire_sample)
    mav: Any = _or_skip(mavlink._dialect)
    parser = mav.MAVLink(None)
    (command,) = parser.parse_buffer(s.command)
    assert command.get_type() == "COMMAND_LONG"
    assert command.command == mav.MAV_CMD_DO_SET_SERVO
    assert (command.param1, command.param2) == (9.0, float(mavlink.SERVO_9_AT_90_US))
    assert s.ack is not None
    (ack,) = parser.parse_buffer(s.ack)
    assert ack.get_type() == "COMMAND_ACK"
    assert (ack.command, ack.result) == (mav.MAV_CMD_DO_SET_SERVO, mav.MAV_RESULT_ACCEPTED)


def test_pw_rpc_wire_sample_decodes() -> None:
    s = _sample(pigweed.wire_sample)
    pw = pigweed._Pigweed()
    assert s.ack is not None
    frames = list(pw.decode.FrameDecoder().process(s.command + s.ack))
    assert [f.ok() for f in frames] == [True, True]
    assert {f.address for f in frames} == {pigweed.RPC_ADDRESS}
    request, response = (pw.packets.decode(f.data) for f in frames)
    body = pw.packets.decode_payload(request, pw.pb.SetAngleRequest)
    assert (body.pin, body.degrees) == (9, 90)
    assert request.call_id == response.call_id
    assert (request.service_id, request.method_id) == (pw.service_id, pw.method_id)


def test_firmata_wire_sample_is_an_analog_message() -> None:
    s = _sample(firmata_peer.wire_sample)
    # Firmata's ANALOG_MESSAGE: 0xE0 | pin, then the value as two 7-bit bytes, LSB first.
    assert s.command == bytes((0xE0 | 9, 90 & 0x7F, 90 >> 7))
    assert s.setup is not None and s.setup.startswith(b"\xf0\x70\x09")  # SERVO_CONFIG pin 9
    assert s.ack is None


def test_telemetrix_wire_sample_is_a_servo_write() -> None:
    s = _sample(telemetrix_peer.wire_sample)
    constants: Any = _or_skip(lambda: require("telemetrix.private_constants", "telemetrix"))
    assert s.command == bytes((3, constants.PrivateConstants.SERVO_WRITE, 9, 90))
    assert s.ack is None


def test_serialtransfer_wire_sample_parses_back() -> None:
    s = _sample(serialtransfer.wire_sample)
    port = serialtransfer.MemoryPort()
    link = serialtransfer._transfer(port)
    port.load(s.command)
    assert link.available() == 2
    assert (link.rx_obj("B", 0), link.rx_obj("B", 1)) == (9, 90)


def test_wire_section_lists_every_installed_library() -> None:
    samples, skipped = wire.collect()
    names = {s.library for s in samples} | {label for label, _package in skipped}
    assert names == {label for label, _factory in wire.PEERS}
    assert samples[0].library == "protoduino"


# --- the report generator ----------------------------------------------------------------


def test_runner_writes_a_report(tmp_path: Path) -> None:
    out = tmp_path / "performance.md"
    args = ["--frames", "40", "--reps", "1", "--only", "receive", "--only", "wire"]
    assert runner.main([*args, "--out", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    for heading in ("## Targets", "## Machine", "## 1. Host receive path", "## 4. Bytes on the"):
        assert heading in text
    assert "## 2. Round trip" not in text  # --only leaves the other sections out
    assert "### Where the time goes" in text
    for label, _decoder in protoduino.DECODERS:
        assert f"| {label} |" in text
    command = protoduino.wire_sample().command
    assert " ".join(f"{b:02x}" for b in command) in text
    for link in ("perf/receive.png", "perf/receive_stages.png", "perf/wire.png"):
        if link in text:
            assert (tmp_path / link).stat().st_size > 0


def test_chart_helpers_for_latency_and_throughput(tmp_path: Path) -> None:
    """The latency histogram and throughput-vs-window charts of parts 2 and 3."""
    from bench import charts

    _or_skip(charts.pyplot)
    hist = charts.histogram(
        tmp_path / "latency.png",
        {"simulated": [1.0, 1.2, 1.1, 2.0], "emulated Uno": [3.0, 3.5, 3.2]},
        title="round trip",
        xlabel="ms",
        bins=5,
        vlines={"wire time": 2.9},
    )
    line = charts.lines(
        tmp_path / "window.png",
        [1, 2, 4, 8],
        {"acked commands/s": [100.0, 190.0, 350.0, 420.0]},
        title="throughput",
        xlabel="window",
        ylabel="commands/s",
        hlines={"line rate": 440.0},
    )
    for path in (hist, line):
        assert path.read_bytes().startswith(b"\x89PNG")


def test_ratio_is_the_median_of_per_round_ratios() -> None:
    base = protoduino.rx_case(10, CHUNK, SEED)
    other = dataclasses.replace(base, frames=5)
    a = receive.RxResult(base, Timing((1.0, 2.0, 4.0)))  # 10, 5, 2.5 frames/s
    c = receive.RxResult(other, Timing((1.0, 8.0, 4.0)))  # 5, 0.625, 1.25 frames/s
    assert a.frames_per_s / c.frames_per_s == pytest.approx(4.0)  # ratio of the medians
    assert a.ratio(c) == pytest.approx(2.0)  # rounds: 2, 8, 2
    assert c.ratio(a) == pytest.approx(0.5)
    frames_per_s, _bytes_per_s = c.scaled_to(a)
    assert frames_per_s == pytest.approx(2.5)


# --- parts 2, 3 and 5: boards ------------------------------------------------------------


def _need(backend: str) -> None:
    missing = boards.missing_tool(backend)
    if missing is not None:
        pytest.skip(f"{missing} is not installed (needed for the {backend} board)")


def test_percentiles_by_nearest_rank() -> None:
    p = boards.Percentiles.of([float(x) for x in range(100, 0, -1)])  # 1..100, shuffled order
    assert (p.n, p.low, p.high) == (100, 1.0, 100.0)
    assert p.p50 == pytest.approx(50.5)
    assert (p.p90, p.p99) == (90.0, 99.0)
    with pytest.raises(ValueError):
        boards.Percentiles.of([])


def test_line_rates_come_from_the_frames() -> None:
    command, ack = roundtrip.wire_frames("servo")
    line = throughput.servo_line()
    assert (line.command_bytes, line.ack_bytes) == (len(command), len(ack))
    # The emulated Uno's line: 11 bits a byte at 16 MHz / (8 x 17) baud.
    emulated = 16e6 / (8 * 17) / 11
    assert line.both == pytest.approx(emulated / (len(command) + len(ack)))
    assert line.duplex == pytest.approx(emulated / max(len(command), len(ack)))
    assert line.duplex > line.both


@pytest.mark.parametrize("make", [roundtrip.ping_frames, throughput.ping_frames_64])
def test_ping_frames_decode_to_a_ping_and_its_echo(make: Callable[[], tuple[bytes, bytes]]) -> None:
    command, ack = make()
    dec = StreamDecoder()
    (cmd_packet,), (ack_packet,) = dec.feed(command), dec.feed(ack)
    assert isinstance(cmd_packet, Packet) and isinstance(ack_packet, Packet)
    msg = pb.ArduinoIn.FromString(cmd_packet.payload)
    reply = pb.ArduinoOut.FromString(ack_packet.payload)
    assert msg.WhichOneof("data") == "ping"
    assert reply.ack.message_id == msg.message_id
    # The firmware always answers a Ping with the echo field set, empty or not.
    assert reply.ack.WhichOneof("result") == "ping_echo"
    assert reply.ack.ping_echo == msg.ping.payload


def test_drive_makes_every_call_and_counts_failures() -> None:
    calls: list[int] = []

    def op(i: int) -> None:
        calls.append(i)
        if i % 3 == 0:
            raise CommandRejectedError(1, "refused")

    seconds, ok, failed = throughput.drive(op, window=4, total=10)
    # 10 calls over 4 threads: 3, 3, 2, 2; in each thread i = 0, 1, ...
    assert sorted(calls) == [0, 0, 0, 0, 1, 1, 1, 1, 2, 2]
    assert (ok, failed) == (6, 4)
    assert seconds > 0


def test_profile_names_and_groups() -> None:
    assert firmware.clean_name("pd_link_send.constprop.41") == "pd_link_send"
    assert firmware.clean_name("drive_digital.isra.0.lto_priv.53") == "drive_digital"
    assert firmware.clean_name("main") == "main"
    assert firmware.group_of("load_descriptor_values").startswith("nanopb")
    assert firmware.group_of("pb_decode_tag").startswith("nanopb")
    assert firmware.group_of("fast_uint").startswith("generated decoders")
    assert firmware.group_of("pd_crc16_update").startswith("CRC")
    assert firmware.group_of("__vector_18") == "interrupt handlers"
    assert firmware.group_of("pd_link_send").startswith("frame transmit")
    assert firmware.group_of("something_new") == "everything else"
    # The cycles a block added: its profile less the idle one scaled to the same time,
    # the displaced idle cycles (negative differences) not counted.
    idle = Counter({0x100: 1_000, 0x200: 500})
    busy = Counter({0x100: 1_500, 0x200: 900, 0x300: 700})
    assert firmware.added_cycles(idle, 10_000, busy, 20_000) == 700


def test_stats_only_on_the_emulated_uno(tmp_path: Path) -> None:
    with pytest.raises(ValueError), boards.started("native", stats=tmp_path / "s.jsonl"):
        pass


def test_raw_client_round_trip_on_the_simulated_board() -> None:
    _need("native")
    with boards.started("native") as sim, boards.RawClient(sim.port) as raw:
        msg = pb.ArduinoIn()
        msg.ping.payload = b"bench"
        assert raw.call(msg) > 0
        assert raw.call(roundtrip.RAW_MESSAGES["ping"](0)) > 0


def _built_elf() -> Path:
    _need("avr")
    from protoduino_dev import build

    return build.build_firmware()


@pytest.mark.avr
def test_footprint_agrees_with_avr_size_berkeley() -> None:
    elf = _built_elf()
    size = firmware.footprint(elf)
    out = subprocess.run(
        [shutil.which("avr-size") or "avr-size", "-B", str(elf)],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    assert (size.text, size.data, size.bss) == (text, data, bss)
    assert (size.flash, size.ram) == (text + data, data + bss)


@pytest.mark.avr
def test_emulator_counters_count_uart_bytes_and_agree_with_the_profile(tmp_path: Path) -> None:
    """--stats counts every UART byte exactly; --profile charges the same awake cycles."""
    elf = _built_elf()
    stats, profile = tmp_path / "stats.jsonl", tmp_path / "profile.txt"
    command, ack = roundtrip.ping_frames()  # the raw client's ids are 5-byte varints too
    n = 6
    with boards.started("avr", stats=stats, profile=profile) as sim:
        counter = boards.CycleCounter(sim, stats)
        with boards.RawClient(sim.port) as raw:
            before = counter.snapshot()
            for i in range(n):
                raw.call(roundtrip.RAW_MESSAGES["ping"](i))
            # The last Ack's final byte leaves the UART after the host read it: wait for the
            # counter, not for a time (the deadline bounds a failure only).
            deadline = time.monotonic() + 10.0
            delta = counter.snapshot() - before
            while delta.uart_tx < n * len(ack) and time.monotonic() < deadline:
                time.sleep(0.01)
                delta = counter.snapshot() - before
        by_function = firmware.read_profile(profile, firmware.Symbols.of(elf))
    assert (delta.uart_rx, delta.uart_tx) == (n * len(command), n * len(ack))
    assert 0 < delta.awake < delta.cycles
    profiled = sum(by_function.values())
    # Interrupt entries taken while asleep count as awake but have no address to go to.
    assert 0.9 * delta.awake <= profiled <= delta.awake
    assert by_function["pd_link_send"] > 0
    assert any(name.startswith("pb_") for name in by_function)


@pytest.mark.avr
def test_echo_calibration_through_the_runner_test_program() -> None:
    _need("avr")
    with boards.started_echo() as sim:
        trips = boards.echo_round_trips(sim.port, 3, warmup=1)
    assert len(trips) == 3
    assert all(t > 0 for t in trips)


@pytest.mark.avr
def test_runner_writes_the_board_sections(tmp_path: Path) -> None:
    _need("native")
    _need("avr")
    out = tmp_path / "performance.md"
    sections = ["--only", "roundtrip", "--only", "throughput", "--only", "firmware"]
    assert runner.main([*sections, "--samples", "3", "--commands", "8", "--out", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    for heading in ("## 2. Round trip", "## 3. Throughput", "## 5. Firmware"):
        assert heading in text
    assert "## 1. Host receive path" not in text
    for label, _ in boards.BACKENDS:
        assert f"| {boards.LABELS[label]} | servo write |" in text
    assert "### Where the emulated Uno's round trip goes" in text
    # The round trip at the rate the Board agrees on, beside 115200's: measured, not skipped.
    assert "### At the agreed rate" in text and "agreed on 1,000,000 baud" in text
    assert "| servo write |" in text.split("### At the agreed rate")[1]
    assert "echoes one byte in" in text  # the emulator's own share, measured
    assert "### Profile of a servo write on the Uno" in text
    assert "`pd_link_send`" in text
    # Issue 35: the same write's cycles beside StandardFirmata's, on the same runner.
    firmata = text.split("### The same write on StandardFirmata")[1]
    assert "| digital write |" in firmata and "| servo write |" in firmata
    assert "not measured" not in text  # every target of parts 2, 3 and 5 has a verdict
    for chart in ("roundtrip_avr", "roundtrip_native", "throughput_avr", "throughput_native"):
        link = f"perf/{chart}.png"
        if link in text:
            assert (tmp_path / link).read_bytes().startswith(b"\x89PNG")


@pytest.mark.avr
def test_motion_section_on_both_boards() -> None:
    """Part 6: every pose case and every rate method measured on both boards, none lost."""
    _need("native")
    _need("avr")
    from bench import motion
    from bench.core import Context

    text = motion.run(Context(samples=20, commands=30, chart_dir=None)).markdown
    assert "not run" not in text
    for label, _ in boards.BACKENDS:
        assert f"### {boards.LABELS[label][0].upper()}{boards.LABELS[label][1:]}" in text
    for joints in motion.JOINTS:
        for method in motion.METHODS:
            rows = [
                line for line in text.splitlines() if line.startswith(f"| {joints} | {method} |")
            ]
            assert len(rows) == 2  # one per board
            assert all(row.endswith("| 0 |") for row in rows)  # no pose lost
    for method in motion.RATE_METHODS:
        assert sum(line.startswith(f"| {method} |") for line in text.splitlines()) == 2


@pytest.mark.avr
def test_mega_section_drives_24_servos_from_three_poses() -> None:
    """Part 11, small: two trials on the emulated Mega, none lost; each trial is three poses
    of eight (six Acks timed), every one of the 24 pins shows servo lines at its new widths
    (the board's trace), and the report states the line rate it depends on."""
    _need("avr")
    from bench import mega

    run = mega.measure(trials=2, seed=SEED)
    assert run.error is None, run.error
    assert (run.trials, run.lost) == (2, 0)
    assert (len(run.pose_s), len(run.poses_s), len(run.spread_s)) == (6, 2, 2)
    assert len(run.deviations) >= 2 * len(mega.PINS)  # every pin's first new line, each trial
    assert all(d <= mega.MATCH_US for d in run.deviations)
    text = mega.report(run)
    assert "24 servos on the emulated Mega 2560" in text and "11 bits" in text
    assert "| the three poses, first call to last Ack (host clock) |" in text


@pytest.mark.avr
def test_loop_section_runs_a_1khz_loop_on_both_boards() -> None:
    """Part 12, short: the 1 kHz loop on both boards; every period counted (sent or missed),
    every pose sent was acknowledged and timed, the six analog channels counted, and the
    emulated Uno's wire time and awake share measured (the simulated board has neither)."""
    _need("native")
    _need("avr")
    from bench import loop

    runs = [loop.measure(backend, 0.3) for backend, _ in boards.BACKENDS]
    for run in runs:
        assert run.error is None, run.error
        assert run.baud == 1_000_000  # the rate the Board agreed on
        assert run.periods >= 0.3 / loop.PERIOD - 1
        assert run.missed == run.late + run.behind
        assert 0 < len(run.pose_s) == run.periods - run.missed
        assert sorted(run.rates) == [14, 15, 16, 17, 18, 19]
    native, avr = runs
    assert native.wire_s is None and native.awake is None
    assert avr.wire_s is not None and 0 < avr.wire_s < loop.PERIOD
    assert avr.awake is not None and 0 < avr.awake <= 1
    text = loop.report(runs)
    assert "| emulated Uno (avr), 1,000,000 baud |" in text and "11 bits" in text


@pytest.mark.avr
def test_inputs_section_on_both_boards() -> None:
    """Part 7: every edge reached its callback, every channel streamed, every interlock trial
    stopped the motor at the pin, on both boards; and the avr targets have a verdict."""
    _need("native")
    _need("avr")
    from bench import inputs

    results = inputs.collect(trials=4, seconds=0.3, pings=3)
    assert [r.backend for r in results] == [b for b, _ in boards.BACKENDS]
    for result in results:
        assert result.error is None, result.error
        assert result.latency_lost == 0 and len(result.latency) == 4
        assert sorted(result.per_channel) == [14, 15, 16, 17, 18, 19]
        assert all(rate > 0 for rate in result.per_channel.values())
        assert len(result.idle_rtt) == 3 and result.stream_rtt
        assert result.reaction_lost == 0 and len(result.reaction) == 4
        assert all(r >= 0 for r in result.reaction)
        # Each edge's report was sized on the wire: a header, the masks, a CRC at least.
        assert len(result.report_bytes) >= 4 and min(result.report_bytes) >= 12
    out = pb.ArduinoOut()
    out.input_report.digital_pins = b"\x01"
    assert out.SerializeToString()[:1] == inputs.REPORT_TAG


@pytest.mark.avr
def test_ros2_section_on_the_emulated_uno() -> None:
    """Part 8: every Twist reached both motor pins, every edge its DDS sample, every analog
    topic streamed, and the commands and reports were found in the bridge's capture."""
    _need("avr")
    pytest.importorskip("cyclonedds", reason="cyclonedds (the ros2 extra) is missing")
    pytest.importorskip("yaml", reason="PyYAML (the ros2 extra) is missing")
    from bench import ros2, ros2_rclpy

    result = ros2.collect(trials=4, seconds=0.5)
    assert result.error is None, result.error
    for phase, trials in ((result.idle, 4), (result.streaming, 3)):
        assert phase is not None
        assert phase.drive_lost == 0 and len(phase.drive) == trials
        # The right motor is written after the left one's Ack: it comes later at the pins.
        assert all(t.to_right > t.to_left for t in phase.drive)
        assert all(t.to_sent is not None for t in phase.drive)
        assert len(phase.command_bytes) == trials and min(phase.command_bytes) >= 12
    assert result.idle is not None and result.streaming is not None
    assert result.idle.inputs_lost == 0 and len(result.idle.inputs) == 4
    assert len(result.idle.report_bytes) >= 4
    assert sorted(result.streaming.device_rates) == list(ros2.ANALOG_PINS)
    assert all(rate > 0 for rate in result.streaming.topic_rates.values())
    assert len(result.streaming.topic_rates) == len(ros2.ANALOG_PINS)
    # The real ROS 2 node (rclpy on Fast DDS): every Twist at both motor pins, every edge at
    # its callback, every encoder pulse in an Odometry at its callback.
    if not ros2_rclpy.PYTHON.exists():
        pytest.skip(f"rclpy is not installed ({ros2_rclpy.PYTHON}: ./tools/dev.sh setup)")
    real = result.rclpy
    assert real is not None, result.rclpy_error
    assert real.drive_lost == 0 and len(real.drive) == 4
    assert all(t.to_right > t.to_left > 0 for t in real.drive)
    assert all(t.to_sent is not None for t in real.drive)
    assert real.inputs_lost == 0 and len(real.inputs) == 4 and min(real.inputs) > 0
    assert real.odometry_lost == 0 and len(real.odometry) == 4 and min(real.odometry) > 0
    assert result.rclpy_versions.startswith("rclpy 9.1.2 on rmw_fastrtps_cpp")


def test_the_ros2_part_imports_one_way() -> None:
    """Part 8's helpers are leaves: bench.ros2 uses them, they use nothing of the bench (issue
    36 found bench/ros2.py and bench/ros2_peer.py importing each other)."""
    import ast

    for name in ("ros2_peer", "ros2_rclpy"):
        tree = ast.parse((ROOT / "bench" / f"{name}.py").read_text())
        used = [
            "." * node.level + (node.module or "")
            for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom)
            and (node.level > 0 or (node.module or "").split(".")[0] == "bench")
        ]
        used += [
            alias.name
            for node in ast.walk(tree)
            if isinstance(node, ast.Import)
            for alias in node.names
            if alias.name.split(".")[0] == "bench"
        ]
        assert used == [], f"bench/{name}.py imports {used}"


def test_report_quote_replaces_only_between_markers(tmp_path: Path) -> None:
    from bench import report

    doc = tmp_path / "README.md"
    doc.write_text("a <!-- bench:footprint -->old<!-- /bench:footprint --> b\nold\n")
    other = tmp_path / "other.md"
    other.write_text("no markers: old\n")
    changed = report.quote([doc, other], {"footprint": "flash 1 B"})
    assert changed == [doc]
    assert (
        doc.read_text() == "a <!-- bench:footprint -->flash 1 B<!-- /bench:footprint --> b\nold\n"
    )
    assert other.read_text() == "no markers: old\n"
    assert report.quote([doc], {"footprint": "flash 1 B"}) == []  # nothing left to change


def _firmata_hex() -> Path:
    """The race's StandardFirmata hex: setup fetched it (tools/dev.sh setup, which CI runs)."""
    from bench import race

    assert race.FIRMATA_HEX.exists(), f"StandardFirmata's hex is missing: run {race.FETCH_STEP}"
    return race.FIRMATA_HEX


def test_firmata_footprint_from_its_hex() -> None:
    """Flash is the hex's bytes; static RAM the end of .bss its start-up code clears (940 B,
    as read from the same code by hand: ../shared/TOOLCHAIN.md, Peers and engines)."""
    if shutil.which("avr-objcopy") is None:
        pytest.skip("avr-objcopy is not installed (binutils-avr)")
    from bench.peers import firmata_board

    size = firmata_board.hex_footprint(_firmata_hex())
    assert (size.flash, size.static_ram) == (12_194, 940)


def test_race_finds_each_pins_last_fall() -> None:
    from bench import race

    events: list[dict[str, Any]] = [
        {"t": 1.0, "pin": 13, "mode": "servo", "value": 1500},
        {"t": 1.5, "pin": 2, "mode": "digital", "value": 0},
        {"t": 2.0, "pin": 13, "mode": "servo", "value": 0},
        {"t": 2.5, "pin": 4, "mode": "digital", "value": 1},
    ]
    # Pin 4 is high at the end: no last fall yet; pin 7 never moved.
    assert race._last_falls(events, (2, 4, 7, 13)) == {2: 1.5, 13: 2.0}


def test_race_line_times_from_simavrs_byte() -> None:
    from bench import race

    line = race.Line(11 * 8 * 17)  # U2X, UBRR 16: protoduino's 115200
    assert line.baud == pytest.approx(16e6 / (8 * 17))
    assert line.board_byte_us == pytest.approx(93.5)
    assert line.host_byte_us == pytest.approx(85.0)


def test_race_wire_time_counts_each_direction_at_its_own_byte_time() -> None:
    """The servo round trip's wire time: the command's bytes at 10 bits into the board, the
    Ack's at simavr's 11 bits out of it; each call less its own frames' time."""
    from bench import race

    line = race.Line(11 * 8 * 17)  # 115200: 85.0 us a byte in, 93.5 us out
    assert line.wire_seconds(17, 15) == pytest.approx((17 * 85.0 + 15 * 93.5) / 1e6)
    assert line.wire_seconds(0, 0) == 0.0
    got = race.beyond_wire([0.004, 0.0035], [(17, 15), (16, 14)], line)
    assert got == pytest.approx([0.004 - 2.8475e-3, 0.0035 - 2.669e-3])
    with pytest.raises(ValueError):
        race.beyond_wire([0.004], [(17, 15), (16, 14)], line)


def test_race_round_trip_target_is_the_median_of_the_runs_p50s() -> None:
    """The target row judges the median of the runs' p50s at every rate, and not at all when
    a run is missing; the table says which wire time it subtracted."""
    from bench import race

    line = race.Line(11 * 8 * 17)

    def runs(*p50s_ms: float) -> list[Any]:
        return [race.RoundTripRun(115_200, line, [p / 1e3] * 3, [(17, 15)] * 3) for p in p50s_ms]

    fast = [race.RoundTripRun(250_000, race.Line(11 * 8 * 8), [0.2e-3], [(17, 15)])] * 5
    met = race._round_trip_target({115_200: runs(0.4, 0.5, 0.3, 0.45, 0.2), 250_000: fast})
    assert met.met is True and "0.40 ms (0.20-0.50) at 115,200" in met.measured
    # The median, not the best run: three of five over the goal miss it.
    missed = race._round_trip_target({115_200: runs(0.4, 0.6, 0.3, 0.7, 0.9), 250_000: fast})
    assert missed.met is False and "0.60 ms (0.30-0.90)" in missed.measured
    failed = race.RoundTripRun(115_200, error="no board")
    partial = race._round_trip_target({115_200: [*runs(0.1, 0.1, 0.1, 0.1), failed]})
    assert partial.met is None and "4 of 5 runs at 115,200" in partial.measured
    table = race._round_trip_table({115_200: runs(0.4, 0.5, 0.3, 0.45, 0.2)})
    assert "2,848 us: command 17 B x 85.0 us + Ack 15 B x 93.5 us" in table
    assert "| **0.40** | 0.20-0.50 |" in table


def test_race_host_cpu_target_is_every_kinds_median_of_the_runs_on_both_boards() -> None:
    """Issue 35's host CPU row: each call kind's median over the runs, on every board, all
    within the goal; not judged when a run is missing; the table gives median and spread."""
    from bench import race

    def runs(backend: str, *us: float) -> list[Any]:
        return [
            race.HostCpuRun(backend, 1_000_000, dict.fromkeys(race.HOST_CPU_KINDS, u / 1e6))
            for u in us
        ]

    native = runs("native", 30, 50, 40, 20, 45)
    met = race._host_cpu_target({"native": native, "avr": runs("avr", 59, 10, 70, 80, 20)})
    assert met.met is True and met.measured == "40-40 us on native; 59-59 us on avr"
    # The median, not the best run: three of five over the goal miss it.
    missed = race._host_cpu_target({"native": native, "avr": runs("avr", 61, 10, 70, 80, 20)})
    assert missed.met is False and "61-61 us on avr" in missed.measured
    failed = race.HostCpuRun("avr", error="no board")
    partial = race._host_cpu_target({"native": native, "avr": [*runs("avr", 1, 1), failed]})
    assert partial.met is None and "2 of 3 runs on avr" in partial.measured
    table = race._host_cpu_table({"native": native})
    assert "| digital write | **40** (20-50) |" in table and "(5 runs, 1,000,000 baud)" in table


@pytest.mark.avr
def test_race_host_cpu_on_both_boards() -> None:
    """One run of the host CPU measure on each board: every call kind measured."""
    _need("avr")
    _need("native")
    from bench import race

    cpu = race.collect_host_cpu(samples=6, commands=10, seed=SEED, runs=1)
    assert list(cpu) == list(race.HOST_CPU_BOARDS)
    for (run,) in cpu.values():
        assert run.error is None, run.error
        assert list(run.cpu) == list(race.HOST_CPU_KINDS) and all(v > 0 for v in run.cpu.values())
    assert race._host_cpu_target(cpu).met is not None


@pytest.mark.avr
def test_race_servo_round_trips_on_the_emulated_uno() -> None:
    """Part 9's servo round trips: one run at each rate, every call with its own frames."""
    _need("avr")
    from bench import race

    trips = race.collect_round_trips(samples=6, seed=SEED, runs=1)
    assert list(trips) == [115_200, race.FAST_BAUD]
    for nominal, (run,) in trips.items():
        assert run.error is None, run.error
        assert run.baud == nominal and len(run.overheads) == 6 and len(run.sizes) == 6
        assert all(cmd >= 12 and ack >= 8 for cmd, ack in run.sizes)
    assert trips[115_200][0].line == race.Line(11 * 8 * 17)
    assert trips[race.FAST_BAUD][0].line == race.Line(11 * 8 * 2)
    assert race._round_trip_target(trips).met is not None


@pytest.mark.avr
def test_race_on_both_boards() -> None:
    """Part 9: StandardFirmata (the unmodified hex) and protoduino on the same runner; every
    row measured for both, nothing lost; byte counts and line rates exact."""
    _need("avr")
    _firmata_hex()
    _or_skip(lambda: require("pyfirmata2.pyfirmata2", "pyFirmata2"))
    from bench import race

    ours, fast, theirs = race.collect(samples=6, commands=10, seed=SEED, analog_seconds=0.3)
    for run in (ours, fast, theirs):
        assert run.error is None, run.error
        assert run.lost == 0 and len(run.digital) == 6 and len(run.servo) == 5
        assert run.flat is not None and run.flat.changes == 10 and run.flat.seconds > 0
        assert sorted(run.analog) == (list(range(6)) if run is theirs else [14, 15, 16, 17, 18, 19])
        assert all(rate > 0 for rate in run.analog.values())
        assert 0 < run.stack < 2048 - run.static_ram
    # The UART rates the firmwares set: protoduino U2X with UBRR 16, Firmata's 57600 without
    # U2X (the Arduino core's exception for that rate) and UBRR 16; simavr's 11-bit bytes.
    assert ours.line == race.Line(11 * 8 * 17)
    # The agreed rate: UBRR 1 with U2X, 1,000,000 baud (docs/protocol.md 5, *Line rate*).
    assert fast.nominal_baud == race.FAST_BAUD and fast.line == race.Line(11 * 8 * 2)
    assert theirs.line == race.Line(11 * 16 * 17)
    assert theirs.command_bytes == [3]  # DIGITAL_MESSAGE: 0x90 | port, two 7-bit bytes
    assert ours.command_bytes and min(ours.command_bytes) >= 12 and ours.answer_bytes
    assert ours.poses is not None and ours.poses.changes == 20 * len(race.POSE_PINS)
    assert ours.poses.acked is not None and ours.poses.acked <= 0.001  # the pins before the Ack
    assert theirs.poses is None and theirs.flat is not None and theirs.flat.acked is None
    assert (theirs.flash, theirs.static_ram) == (12_194, 940)
    assert set(ours.cpu) == {"digital write", "servo write", "pose (6 outputs)"}
    assert set(theirs.cpu) == {"digital write", "servo write"}
    # The report's rows and the targets come out of these runs, every one filled in.
    for run in (ours, fast, theirs):
        cells = race._cells(run)
        assert set(cells) == set(race.ROWS)
        assert not any(cell.startswith("not run") for cell in cells.values())
    assert [t.met is not None for t in race._targets(ours, theirs, fast)] == [True] * 3
    assert "StandardFirmata's" in race._quote(ours, theirs, fast)
    assert f"at the agreed {race.FAST_BAUD:,}" in race._quote(ours, theirs, fast)


def test_report_merge_replaces_only_the_parts_run() -> None:
    """``--merge``: the parts run replace theirs (sections and target rows), a new part goes in
    its place by number, the others stay as the earlier run left them, and the header says so."""
    from bench import report

    table = "| part | target | goal | measured | verdict |\n|---|---|---|---|---|\n"
    old = (
        "# Performance\n\nheader\n\n## Targets\n\n" + table + "| 1. A | a | g | 1 | met |\n"
        "| 5. F | f | g | old | met |\n| 7. I | i | g | 7 | met |\n\nMissed targets.\n\n"
        "## Machine\n\nm\n\n## 1. A\n\nold one\n\n## 5. F\n\nold five\n\n## 7. I\n\nseven\n"
    )
    new = (
        "# Performance\n\nnew header\n\n## Targets\n\n" + table + "| 5. F | f | g | new | met |\n"
        "| 8. R | r | g | 8 | **missed** |\n\n## Machine\n\nm2\n\n## 5. F\n\nnew five\n\n"
        "## 8. R\n\nrace\n"
    )
    assert report.parts_come([9]) == "Part 9 comes"
    assert report.parts_come([2, 9]) == "Parts 2 and 9 come"
    assert report.parts_come([2, 5, 9]) == "Parts 2, 5 and 9 come"
    merged = report.merge(old, new, "Parts 5 and 8 come from a later run.")
    assert merged.startswith("# Performance\n\nheader\n\n> Parts 5 and 8 come from a later run.\n")
    assert "new header" not in merged and "m2" not in merged and "\nm\n" in merged
    rows = [line for line in merged.splitlines() if line.startswith("| ") and ". " in line[:6]]
    assert [r.split(" | ")[0] for r in rows] == ["| 1. A", "| 5. F", "| 7. I", "| 8. R"]
    assert "| 5. F | f | g | new | met |" in rows and "Missed targets." in merged
    headings = [line for line in merged.splitlines() if line.startswith("## ")]
    assert headings == ["## Targets", "## Machine", "## 1. A", "## 5. F", "## 7. I", "## 8. R"]
    assert "new five" in merged and "old five" not in merged and "old one" in merged
    # A later merge of the same parts replaces the note, one of fewer parts keeps it.
    again = report.merge(merged, new, "Parts 5 and 8 come from a later run, again.")
    assert "later run.\n" not in again and again.count("> Parts") == 1
    # ... as does one in the older wording, and one of a single part.
    older = merged.replace("Parts 5 and 8 come", "Parts 5, 8 come")
    assert report.merge(older, new, "y").count("later run") == 0
    single = report.merge(merged, new, "Part 8 comes from a later run.")
    assert report.merge(single, new, "z").count("later run") == 0
    fewer = new.replace("| 5. F | f | g | new | met |\n", "").split("## 5. F")[0]
    assert report.merge(merged, fewer + "## 8. R\n\nrace\n", "x").count("> Parts") == 1
    assert "> x" in report.merge(merged, fewer + "## 8. R\n\nrace\n", "x")
    # Notes that share a paragraph (a hand edit) are judged one by one: part 9's stays.
    shared = merged.replace(
        "> Parts 5 and 8 come from a later run.\n",
        "> Parts 5 and 8 come from a later run.\n> Part 9 comes from a later run still.\n",
    )
    rerun = report.merge(shared, new, "w")
    assert "Parts 5 and 8 come" not in rerun and "> Part 9 comes from a later run still." in rerun


@pytest.mark.avr
def test_services_section_measures_both_calls_and_the_footprints() -> None:
    """Part 10: a user call and a built-in of the same size on the emulated Uno, and the builds."""
    _need("avr")
    from bench import services
    from bench.core import Context

    ctx = Context(
        samples=5,
        commands=5,
        reps=1,
        frames=10,
        chunk=1024,
        seed=7,
        docs_dir=ROOT / "build",
        chart_dir=None,
        profile=False,
    )
    result = services.run(ctx)
    assert "| user call `StopBlink` (blinker) |" in result.markdown
    assert "| blinker, every pin mode |" in result.markdown
    # The default firmware is this run's build, the baseline of every other row.
    assert "| default firmware (no user service) | " in result.markdown
    assert re.search(
        r"\| blinker, every pin mode \| [\d,]+ \| [\d,]+ \| \+[\d,]+ / \+[\d,]+ \|", result.markdown
    )
    assert len(result.targets) == 1 and result.targets[0].met is not None
    user = pb.ArduinoIn(message_id=0x7FFFFFFF)
    user.user_call.method = 2
    assert len(services.builtin_command()) == len(user.SerializeToString())


def test_race_call_frames_pair_each_command_with_its_ack_across_the_id_wrap() -> None:
    """Ids come round after 127 (protocol version 5): each Ack goes to the latest command of
    its id, a retransmission is not a new command, and the short Ack counts as an Ack."""
    from protoduino.messages import ArduinoIn, serialize_out
    from protoduino.transport import FrameRecord

    from bench import race

    frames = race._CallFrames()

    def send(mid: int, degrees: int) -> None:
        msg = ArduinoIn(message_id=mid)
        msg.servo_control.pin, msg.servo_control.degrees = 9, degrees
        frames(FrameRecord(0.0, "tx", Packet(PacketType.COMMAND, 1, msg.SerializeToString())))

    def ack(mid: int) -> None:
        out = pb.ArduinoOut()
        out.ack.message_id = mid
        frames(FrameRecord(0.0, "rx", Packet(PacketType.DATA, 1, serialize_out(out))))

    for i in range(130):  # ids 1..127, then 1, 2, 3
        mid = i % 127 + 1
        send(mid, i % 180)
        if i == 5:
            send(mid, i % 180)  # sent again before its Ack: the same command
        ack(mid)
    sizes = frames.sizes(skip=0)
    assert len(sizes) == 130
    assert {a for _c, a in sizes} == {9}  # every Ack the short form's 9 bytes
    send(4, 0)  # no Ack for this one
    with pytest.raises(RuntimeError, match=r"message ids \[4\]"):
        frames.sizes(skip=0)
