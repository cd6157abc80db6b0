"""``protoduino ports``: list serial ports, marking Arduinos by USB id."""

from __future__ import annotations

import argparse
import json

from serial.tools import list_ports

HELP = "list serial ports; Arduinos are marked by their USB vendor id"

#: USB vendor ids of Arduino boards (Arduino LLC, Arduino SRL).
ARDUINO_VIDS = {0x2341: "Arduino", 0x2A03: "Arduino"}
#: USB-serial chips common on Arduino clones (may be anything else, too).
CLONE_CHIPS = {(0x1A86, 0x7523): "CH340", (0x0403, 0x6001): "FTDI FT232R"}


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--json", action="store_true", help="one JSON array, an object per port ([] for none)"
    )
    parser.add_argument("--all", action="store_true", help="include ports without a USB id")


def classify(vid: int | None, pid: int | None) -> str:
    """'arduino', 'clone?' (a USB-serial chip clones use) or ''."""
    if vid in ARDUINO_VIDS:
        return "arduino"
    if (vid, pid) in CLONE_CHIPS:
        return "clone?"
    return ""


def run(args: argparse.Namespace) -> int:
    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    shown = 0
    found: list[dict[str, object]] = []
    for port in ports:
        if port.vid is None and not args.all:
            continue
        shown += 1
        kind = classify(port.vid, port.pid)
        usb = f"{port.vid:04x}:{port.pid:04x}" if port.vid is not None else ""
        if args.json:
            obj: dict[str, object] = {
                "device": port.device,
                "description": port.description,
                "usb_id": usb or None,
                "serial_number": port.serial_number,
                "arduino": kind == "arduino",
                "kind": kind or None,
            }
            found.append(obj)
        else:
            mark = {"arduino": "*", "clone?": "?"}.get(kind, " ")
            print(f"{mark} {port.device:<20} {usb:<10} {port.description}")
    if args.json:
        print(json.dumps(found))
    elif not shown:
        print("no USB serial ports found (--all lists the others)")
    else:
        print("(* Arduino USB id, ? USB-serial chip used by clones)")
    return 0
