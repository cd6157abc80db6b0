"""Code generation for both sides of the link, from ``proto/protoduino.proto``.

One function, :func:`generate`, writes:

* ``host/protoduino/_generated/protoduino_pb2.py`` and ``.pyi``, and the same for
  ``protoduino_options.proto`` (protoc from ``grpcio-tools``, typed stubs from
  ``mypy-protobuf``);
* ``host/protoduino/_generated/schema_id.py`` with ``SCHEMA_ID``;
* ``firmware/generated/protoduino.pb.[ch]`` (nanopb 0.4.7, the version of the C
  runtime the firmware is built against; the sizes nanopb leaves out for messages
  with a callback field, DeviceInfo's pin table, as if it were static at its
  ``max_size``: :func:`sized_callbacks`) and ``firmware/generated/pd_schema.h``
  with ``PD_SCHEMA_ID``;
* ``firmware/generated/pd_protocol.h``: the protocol constants and enumerations the
  firmware uses, from ``host/protoduino/constants.py`` (the one place they are written),
  and the firmware's version, the package's (``host/protoduino/_version.py``);
* the built-in command and pin-mode tables from the schema's options
  (:mod:`protoduino_dev.cmdtables`): ``firmware/generated/pd_tables.h``,
  ``firmware/generated/pd_features.mk`` and ``host/protoduino/_generated/tables.py``;
* ``firmware/generated/pd_fastdec.h``: specialised decoders of the pin modes' Controls
  (:mod:`protoduino_dev.fastdec`), held to nanopb's decode by the firmware's tests.

SCHEMA_ID (docs/protocol.md section 5) is the CRC-32 of the deterministic
serialisation of the schema's ``FileDescriptorSet`` (protoduino.proto and
protoduino_options.proto, not the protobuf files they import) without source info:
it changes when any message, field, enum or option in the schema changes (a
command's or pin mode's declaration too), but not with comments or formatting.
Both sides take it from this one computation.

Everything written is deterministic, so the committed files can be compared
against a fresh run (``tests/contract/test_codegen.py``). The generator tools are dev
dependencies: this module imports them only when it runs.
"""

from __future__ import annotations

import functools
import importlib.util
import re
import sys
import tempfile
import zlib
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from types import ModuleType

from . import cmdtables, fastdec

PROTO_NAME = "protoduino.proto"
#: The custom options' declarations, imported by PROTO_NAME (no wire messages).
OPTIONS_PROTO = cmdtables.OPTIONS_PROTO
OPTIONS_NAME = "protoduino.options"

#: Paths (relative to the repository root) of every generated file.
GENERATED_FILES = (
    "host/protoduino/_generated/protoduino_pb2.py",
    "host/protoduino/_generated/protoduino_pb2.pyi",
    "host/protoduino/_generated/protoduino_options_pb2.py",
    "host/protoduino/_generated/protoduino_options_pb2.pyi",
    "host/protoduino/_generated/schema_id.py",
    "host/protoduino/_generated/tables.py",
    "firmware/generated/protoduino.pb.c",
    "firmware/generated/protoduino.pb.h",
    "firmware/generated/pd_schema.h",
    "firmware/generated/pd_protocol.h",
    "firmware/generated/pd_tables.h",
    "firmware/generated/pd_fastdec.h",
    "firmware/generated/pd_features.mk",
)
#: The constants' one source, relative to the repository root.
CONSTANTS_SOURCE = "host/protoduino/constants.py"
#: The package's version, which the firmware reports (DeviceInfo.firmware_version).
VERSION_SOURCE = "host/protoduino/_version.py"


class CodegenError(RuntimeError):
    """A generator step failed; the message carries the tool's output."""


@dataclass(frozen=True)
class Result:
    schema_id: int
    files: tuple[Path, ...]


def repo_root() -> Path:
    """The source checkout this module lives in (dev/protoduino_dev/codegen.py)."""
    return Path(__file__).resolve().parents[2]


#: The runtime's helper for the generators' tools, shared with protoduino.servicegen.
TOOLRUN_SOURCE = "host/protoduino/toolrun.py"


@functools.cache
def _toolrun() -> ModuleType:
    # By path, as constants.py: importing protoduino would import the files this writes.
    return _load_by_path("_protoduino_toolrun", repo_root() / TOOLRUN_SOURCE)


def _run(cmd: list[str], cwd: Path) -> None:
    tools = _toolrun()
    try:
        tools.run(cmd, cwd)
    except tools.ToolError as error:
        raise CodegenError(str(error)) from error


def _protoc(args: list[str], cwd: Path) -> None:
    tools = _toolrun()
    try:
        tools.protoc(args, cwd)
    except tools.ToolError as error:
        raise CodegenError(str(error)) from error


def schema_id_of(descriptor_set: bytes) -> int:
    """CRC-32 of a FileDescriptorSet re-serialised deterministically.

    protobuf's own files (``google/protobuf/descriptor.proto``, which the options
    import) are left out: they come with the protoc version, not from the schema.
    """
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(descriptor_set)
    own = [f for f in fds.file if not f.name.startswith("google/protobuf/")]
    del fds.file[:]
    fds.file.extend(own)
    for f in fds.file:
        f.ClearField("source_code_info")
    return zlib.crc32(fds.SerializeToString(deterministic=True)) & 0xFFFFFFFF


def generate(out_root: Path | None = None, proto_dir: Path | None = None) -> Result:
    """Generate every file in :data:`GENERATED_FILES` below ``out_root``.

    ``out_root`` defaults to the repository root; tests pass a temporary
    folder and compare.
    """
    root = repo_root()
    out_root = out_root or root
    proto_dir = proto_dir or root / "proto"
    py_out = out_root / "host/protoduino/_generated"
    c_out = out_root / "firmware/generated"
    py_out.mkdir(parents=True, exist_ok=True)
    c_out.mkdir(parents=True, exist_ok=True)

    with tempfile.TemporaryDirectory() as tmp:
        desc_path = Path(tmp) / "protoduino.desc"
        _protoc(
            ["-I.", "--include_imports", f"--descriptor_set_out={desc_path}", PROTO_NAME],
            proto_dir,
        )
        schema_id = schema_id_of(desc_path.read_bytes())
        tables = cmdtables.read_tables(desc_path.read_bytes())
        hot = {mode.control for mode in tables.pin_modes if mode.control is not None}
        fast = fastdec.fast_members(desc_path.read_bytes(), hot)

        _protoc(
            [
                "-I.",
                f"--python_out={py_out}",
                f"--mypy_out={py_out}",
                f"--plugin=protoc-gen-mypy={_mypy_plugin()}",
                PROTO_NAME,
                OPTIONS_PROTO,
            ],
            proto_dir,
        )
        _nanopb(proto_dir, proto_dir / OPTIONS_NAME, c_out)
        # The same schema with its callback fields static at their max_size: the
        # sizes nanopb leaves out for a message with a callback (sized_callbacks).
        static_dir = Path(tmp) / "static"
        static_dir.mkdir()
        static_options = static_dir / OPTIONS_NAME
        static_options.write_text(
            re.sub(r"type:FT_CALLBACK\s*", "", (proto_dir / OPTIONS_NAME).read_text())
        )
        _nanopb(proto_dir, static_options, static_dir)
        static_header = (static_dir / "protoduino.pb.h").read_text()

    pb2 = py_out / "protoduino_pb2.py"
    pb2.write_text(package_imports(pb2.read_text()))
    header = c_out / "protoduino.pb.h"
    header.write_text(sized_callbacks(share_descriptors(header.read_text()), static_header))
    (py_out / "schema_id.py").write_text(
        '"""Generated by `protoduino gen` from proto/protoduino.proto. Do not edit."""\n\n'
        f"SCHEMA_ID = 0x{schema_id:08X}\n"
    )
    (c_out / "pd_schema.h").write_text(
        "/* Generated by `protoduino gen` from proto/protoduino.proto. Do not edit. */\n"
        "#ifndef PD_SCHEMA_H\n#define PD_SCHEMA_H\n\n"
        "/* CRC-32 of the schema's deterministic FileDescriptorSet (docs/protocol.md 5). */\n"
        f"#define PD_SCHEMA_ID 0x{schema_id:08X}UL\n\n"
        "#endif /* PD_SCHEMA_H */\n"
    )
    (c_out / "pd_protocol.h").write_text(
        protocol_header(root / CONSTANTS_SOURCE, root / VERSION_SOURCE)
    )
    (c_out / "pd_tables.h").write_text(cmdtables.c_header(tables))
    (c_out / "pd_fastdec.h").write_text(fastdec.c_header(fast))
    (c_out / "pd_features.mk").write_text(cmdtables.make_fragment(tables))
    (py_out / "tables.py").write_text(cmdtables.python_module(tables))
    return Result(schema_id, tuple(out_root / p for p in GENERATED_FILES))


def _nanopb(proto_dir: Path, options: Path, out: Path) -> None:
    _run(
        [
            sys.executable,
            "-W",
            "ignore",
            "-m",
            "nanopb.generator.nanopb_generator",
            "-I",
            str(proto_dir),
            "-f",
            str(options),
            "-D",
            str(out),
            "--error-on-unmatched",
            "-q",
            # The options are for the generators: nothing on the device reads them.
            "-x",
            OPTIONS_PROTO,
            str(proto_dir / PROTO_NAME),
        ],
        proto_dir,
    )


_UNSIZED = re.compile(r"^/\* (protoduino_\w+_size) depends on runtime parameters \*/$", re.M)
_SIZE = re.compile(r"^#define (protoduino_\w+_size)\s+(\d+)$", re.M)


def sized_callbacks(header: str, static_header: str) -> str:
    """``header`` with the sizes nanopb leaves out for a message with a callback field
    (DeviceInfo.pins, written by the device's encoder from the board's table): each as
    if its callbacks were static at their ``max_size`` (``static_header``, nanopb's
    output for that schema), the bound the device's encoder keeps them within."""
    sizes = dict(_SIZE.findall(static_header))

    def size(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in sizes:
            raise CodegenError(f"{name}: no max_size for its callback fields")
        return f"#define {name:<40} {sizes[name]} /* callbacks at their max_size */"

    return _UNSIZED.sub(size, header)


def package_imports(source: str) -> str:
    """protoc's ``import protoduino_options_pb2`` as an import from the same package.

    protoc writes imports relative to its include path, as if ``_generated`` were on
    sys.path; the package imports it as ``protoduino._generated``.
    """
    stem = OPTIONS_PROTO.removesuffix(".proto")
    return re.sub(rf"^import {stem}_pb2 as ", f"from . import {stem}_pb2 as ", source, flags=re.M)


def _load_constants(path: Path) -> ModuleType:
    return _load_by_path("_protoduino_constants", path)


def _load_by_path(name: str, path: Path) -> ModuleType:
    # By path, not `import protoduino.<module>`: the package imports generated files that a
    # fresh checkout may not have yet, and the checkout's file is the source, whatever is
    # installed.
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise CodegenError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _doc_comments(source: str) -> dict[str, str]:
    """NAME -> the ``#:`` comment lines just above its assignment, joined."""
    docs: dict[str, str] = {}
    pending: list[str] = []
    for line in source.splitlines():
        if line.startswith("#:"):
            pending.append(line[2:].strip())
            continue
        match = re.match(r"([A-Z][A-Z0-9_]*)\s*[:=]", line)
        if match and pending:
            docs[match.group(1)] = " ".join(pending)
        pending = []
    return docs


def protocol_header(constants_path: Path, version_path: Path) -> str:
    """firmware/generated/pd_protocol.h from constants.py's FIRMWARE_CONSTANTS and _ENUMS,
    and the firmware's version from _version.py."""
    constants = _load_constants(constants_path)
    version = _load_by_path("_protoduino_version", version_path).__version__
    if not re.fullmatch(r"[0-9A-Za-z.+-]+", version):
        raise CodegenError(f"{VERSION_SOURCE}: not a version for a C string: {version!r}")
    docs = _doc_comments(constants_path.read_text())
    lines = [
        f"/* Generated by `protoduino gen` from {CONSTANTS_SOURCE} and {VERSION_SOURCE}. */",
        "/* Do not edit. */",
        "/*",
        " * The protocol constants (docs/protocol.md section 8) and wire enumerations that the",
        " * firmware uses. Durations are in milliseconds: the device's clock counts them.",
        " */",
        "#ifndef PD_PROTOCOL_H",
        "#define PD_PROTOCOL_H",
        "",
        "/* DeviceInfo.firmware_version: the Python package's version. */",
        f'#define PD_FIRMWARE_VERSION "{version}"',
        "",
    ]
    for name in constants.FIRMWARE_CONSTANTS:
        value = getattr(constants, name, None)
        if name in docs:
            lines.append(f"/* {docs[name]} */")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CodegenError(f"{CONSTANTS_SOURCE}: {name} is not a number: {value!r}")
        if isinstance(value, float):
            lines.append(f"#define PD_{name}_MS {round(value * 1000)}UL")
        else:
            lines.append(f"#define PD_{name} {value}")
    enum: type[IntEnum]
    for prefix, enum in constants.FIRMWARE_ENUMS.items():
        lines += ["", f"/* {enum.__name__}: {enum.__dict__.get('__doc__') or ''} */"]
        lines += [f"#define PD_{prefix}_{m.name} 0x{m.value:02X}" for m in enum]
    lines += ["", "#endif /* PD_PROTOCOL_H */", ""]
    return "\n".join(lines)


_STRUCT = re.compile(r"typedef struct _(\w+) \{\n(.*?)\n\} \1;", re.S)
_FIELDLIST = re.compile(r"#define (\w+)_FIELDLIST\(X, a\) \\\n((?:.*\\\n)*.*)")
_BYTES_TYPEDEF = re.compile(r"^typedef (PB_BYTES_ARRAY_T\(\d+\)) (\w+);$", re.M)
_MSGTYPE = re.compile(r"^#define (\w+_MSGTYPE) (\w+)$", re.M)


def _layout(body: str) -> str:
    """A struct body without its member names (and comments): equal for equal layouts."""
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    body = re.sub(r"\w+(\s*(?:\[[^\]]*\])?\s*;)", r"_\1", body)
    return " ".join(body.split())  # a comment's lines leave blank ones behind


def _fields(fieldlist: str) -> str:
    """A FIELDLIST without its field names: tags, kinds and types only."""
    rows = []
    for line in fieldlist.splitlines():
        parts = [p.strip() for p in line.rstrip(" \\").split(",")]
        if len(parts) >= 6:
            rows.append((parts[1], parts[2], parts[3], parts[-1]))
    return repr(rows)


def share_descriptors(header: str) -> str:
    """Point every submessage field at one descriptor per distinct message shape.

    nanopb keeps each message's descriptor (``pb_msgdesc_t``, 14 B, and its
    submessage table) in the Uno's RAM. Messages with the same fields (tags,
    types, widths) and the same C layout decode and encode alike whatever their
    names: the empty ones (Stop, GetInfo, ...), Heartbeat and Release, DigitalInit
    and DigitalControl, Ping and UserCall. Their fields' MSGTYPE (what a parent's submessage table
    points at) is rewritten to the first of the shape, so the others' descriptors
    are unreferenced and the linker drops them: about 100 B of RAM. Python and
    the wire are untouched; the C structs keep their own names and types.
    """
    # A bytes field's type is a typedef of its own per field: compare its definition.
    arrays = dict((n, d) for d, n in _BYTES_TYPEDEF.findall(header))
    layouts = {
        name: re.sub(r"\b\w+_t\b", lambda m: arrays.get(m.group(0), m.group(0)), _layout(body))
        for name, body in _STRUCT.findall(header)
    }
    shapes: dict[str, str] = {}
    for name, fieldlist in _FIELDLIST.findall(header):
        if (
            name in layouts
            and f"#define {name}_CALLBACK NULL" in header
            and (f"#define {name}_DEFAULT NULL" in header)
        ):
            shapes[name] = layouts[name] + "|" + _fields(fieldlist)
    first: dict[str, str] = {}
    for name in sorted(shapes):
        first.setdefault(shapes[name], name)

    def rewrite(match: re.Match[str]) -> str:
        target = match.group(2)
        shared = first.get(shapes.get(target, ""), target)
        if shared == target:
            return match.group(0)
        return (
            f"/* protoduino gen: {target} has the shape of {shared}: one descriptor "
            f"(codegen.share_descriptors) */\n#define {match.group(1)} {shared}"
        )

    return _MSGTYPE.sub(rewrite, header)


def _mypy_plugin() -> str:
    """Path of mypy-protobuf's protoc plugin, installed beside this Python."""
    exe = Path(sys.executable).parent / "protoc-gen-mypy"
    if not exe.exists():
        raise CodegenError(
            f"protoc-gen-mypy not found next to {sys.executable}; "
            "install the development tools: ./tools/dev.sh setup"
        )
    return str(exe)


if __name__ == "__main__":  # pragma: no cover
    # Runnable as a plain script too, for bootstrapping a checkout whose
    # generated files are missing (the package imports them).
    _result = generate()
    print(f"SCHEMA_ID = 0x{_result.schema_id:08X}")
