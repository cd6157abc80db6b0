"""The host's mirror of the dedupe window (protoduino.testing.DedupeWindow, which the fake
devices answer with) against the firmware's own pd_dedupe.c, step for step.

pd_dedupe.c is compiled on its own into a shared library and driven through ctypes with
seeded random sequences of what the device does with it (a RESET's sync, a command's lookup,
then its done with a status or none); after every step both must hold the same slots, the
same ``next`` and the same N, and every lookup must answer alike.
"""

from __future__ import annotations

import ctypes
import random
import shutil
import subprocess
from pathlib import Path

import pytest
from protoduino.constants import DEDUPE_WINDOW, MAX_MESSAGE_ID
from protoduino.messages import Status
from protoduino.testing import DedupeWindow

ROOT = Path(__file__).resolve().parents[2]
NANOPB = ROOT / ".deps" / "nanopb"
STEPS = 20_000


class _Dedupe(ctypes.Structure):
    _fields_ = [
        ("id", ctypes.c_uint8 * DEDUPE_WINDOW),
        ("status", ctypes.c_uint8 * ((DEDUPE_WINDOW + 1) // 2)),
        ("next", ctypes.c_uint8),
        ("newest", ctypes.c_uint8),
    ]


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    if not NANOPB.is_dir():
        pytest.skip("the nanopb runtime is not fetched (./tools/dev.sh setup)")
    out = tmp_path_factory.mktemp("dedupe") / "pd_dedupe.so"
    subprocess.run(
        [
            "gcc",
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-shared",
            "-fPIC",
            f"-I{ROOT / 'firmware' / 'core'}",
            f"-I{ROOT / 'firmware' / 'generated'}",
            f"-I{NANOPB}",
            str(ROOT / "firmware" / "core" / "pd_dedupe.c"),
            "-o",
            str(out),
        ],
        check=True,
        timeout=120,
    )
    so = ctypes.CDLL(str(out))
    ptr = ctypes.POINTER(_Dedupe)
    so.pd_dedupe_init.argtypes = [ptr]
    so.pd_dedupe_sync.argtypes = [ptr, ctypes.c_uint8, ctypes.c_bool]
    so.pd_dedupe_lookup.argtypes = [ptr, ctypes.c_uint8]
    so.pd_dedupe_lookup.restype = ctypes.c_int
    so.pd_dedupe_done.argtypes = [ptr, ctypes.c_uint8, ctypes.c_int]
    return so


def _same(c: _Dedupe, py: DedupeWindow) -> None:
    assert list(c.id) == py.ids
    assert (c.next, c.newest) == (py.next, py.newest)
    statuses = [(c.status[i >> 1] >> (4 * (i & 1))) & 0x0F for i in range(DEDUPE_WINDOW)]
    assert [s for s, mid in zip(statuses, c.id, strict=True) if mid] == [
        s for s, mid in zip(py.statuses, py.ids, strict=True) if mid
    ]


def _step(lib: ctypes.CDLL, rng: random.Random, c: _Dedupe, py: DedupeWindow, mid: int) -> None:
    """One command with id ``mid`` through both: its lookup, then (unless a repeat) its done."""
    seen = lib.pd_dedupe_lookup(ctypes.byref(c), mid)
    mirrored = py.lookup(mid)
    assert seen == (-1 if mirrored is None else mirrored)
    if seen < 0:  # a repeat is answered and changes nothing
        status = -1 if rng.random() < 0.3 else rng.randrange(16)
        lib.pd_dedupe_done(ctypes.byref(c), mid, status)
        py.done(mid, None if status < 0 else Status.ValueType(status))
    _same(c, py)


@pytest.mark.parametrize("seed", range(4))
def test_the_mirror_keeps_the_firmware_s_window(lib: ctypes.CDLL, seed: int) -> None:
    rng = random.Random(seed)
    c, py = _Dedupe(), DedupeWindow()
    lib.pd_dedupe_init(ctypes.byref(c))
    _same(c, py)
    nxt = 1  # the host's next id: mostly in order, with retransmissions and gaps
    for _ in range(STEPS):
        roll = rng.random()
        if roll < 0.01:
            clear = rng.random() < 0.5
            lib.pd_dedupe_sync(ctypes.byref(c), nxt, clear)
            py.sync(nxt, clear)
            _same(c, py)
            continue
        if roll < 0.75:
            mid, nxt = nxt, nxt % MAX_MESSAGE_ID + 1
        elif roll < 0.95:  # a retransmission, or a first transmission overtaken
            mid = (nxt - 2 - rng.randrange(24)) % MAX_MESSAGE_ID + 1
        else:  # anything, far ahead or behind
            mid = rng.randrange(1, MAX_MESSAGE_ID + 1)
        _step(lib, rng, c, py, mid)


#: How far an id is from N (``(Y - N) mod 127``) where the rule changes: newer up to 63,
#: within reach from 112 (15 behind) on, and the ids between, neither.
EDGES = (0, 1, 2, 15, 16, 17, 62, 63, 64, 65, 110, 111, 112, 113, 125, 126)


@pytest.mark.parametrize("seed", range(4))
def test_the_firmware_s_window_keeps_the_rule_for_any_ids(lib: ctypes.CDLL, seed: int) -> None:
    """No host sends these: ids at every edge of the rule and anywhere, and RESETs to any
    id, resumed or not. pd_dedupe.c skips work that its invariants make needless (add()'s
    search for a stale entry when N moved): the mirror, which does all of it, holds it to
    the rule step for step."""
    rng = random.Random(1000 + seed)
    c, py = _Dedupe(), DedupeWindow()
    lib.pd_dedupe_init(ctypes.byref(c))
    for _ in range(STEPS):
        roll = rng.random()
        if roll < 0.02:
            next_id, clear = rng.randrange(1, MAX_MESSAGE_ID + 1), rng.random() < 0.3
            lib.pd_dedupe_sync(ctypes.byref(c), next_id, clear)
            py.sync(next_id, clear)
            _same(c, py)
            continue
        ahead = rng.choice(EDGES) if roll < 0.6 else rng.randrange(MAX_MESSAGE_ID)
        _step(lib, rng, c, py, (py.newest - 1 + ahead) % MAX_MESSAGE_ID + 1)
