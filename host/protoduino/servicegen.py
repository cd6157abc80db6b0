"""``protoduino gen robot.proto --out DIR``: a user service for both sides (docs/services.md).

From the user's ``robot.proto`` (its messages, one ``service``, an optional error
enum named ``<Service>Error`` (another enum with ``Error`` in its name is refused:
its codes would not be read), nanopb bounds in ``robot.options`` beside it, each
name with or without the package: ``robot.Msg.field`` or ``Msg.field``) this
writes into DIR:

* ``robot.pb.c``, ``robot.pb.h``: nanopb 0.4.7's structs and descriptors (the C
  runtime the firmware is built against);
* ``robot_service.h``, ``robot_service.c``: the handler prototypes the user
  implements, the service table ``pd_user_service`` (firmware/core/pd_user.h)
  and its scratch buffers, sized here from nanopb's structs;
* ``robot_pb2.py``, ``robot_pb2.pyi``: protoc's Python messages and mypy-protobuf's stubs;
* ``robot_client.py``: the typed client (:mod:`protoduino.services`), one method
  per rpc with its ``submit_`` form, an asyncio class, the reports, the error enum
  as named exceptions, and the fingerprint.

Rules: a unary rpc is a call, a server-streaming rpc a report (its request type
is not used; declare ``message Empty {}``); ``option idempotency_level =
NO_SIDE_EFFECTS`` marks a method that only reads (its repeats are answered in full
and the failsafe never refuses it), ``IDEMPOTENT`` one that may be repeated;
every message a method carries is at most 64 bytes on the wire (nanopb's bound,
so every string, bytes and repeated field needs its max_size / max_count) and nests
at most MAX_USER_LEVELS levels of messages (the Uno's stack: see the constants).

The fingerprint is the CRC-32 of the user file's FileDescriptorSet without
source info, serialised deterministically (as SCHEMA_ID is of protoduino's own,
docs/protocol.md section 5): comments do not change it, fields and names do.

The tools (grpcio-tools' protoc, mypy-protobuf, nanopb's generator) are the
``gen`` extra: ``pip install 'protoduino[gen]'``; they are imported only here.
"""

from __future__ import annotations

import builtins
import importlib.util
import re
import sys
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

from . import toolrun
from .errors import ServiceGenError

#: The most bytes a request, reply or report takes on the wire (protoduino.options).
MAX_USER_BYTES = 64

# What a user message costs the Uno's stack. nanopb decodes (and encodes) a message in
# nested calls, one set of frames for each level of messages in messages; measured on the
# emulated Uno with every pin mode in (the runner's --stats low-water mark,
# tests/e2e/test_stack_margin.py), a user call whose request nests L levels takes
# 511, 678, 831 and 999 B of stack for L = 2..5: 145 to 168 B a level.
#: The Uno's stack a level of a user message takes (the measured 168 B, rounded up).
NANOPB_LEVEL_STACK = 170
#: The Uno's stack a user call takes besides its levels (the measured line's intercept).
USER_CALL_STACK = 200
#: The firmware's own deepest stack with every pin mode, which the RAM budget holds
#: (a Pose decoded in full: tests/e2e/test_stack_margin.py measures it).
FIRMWARE_STACK = 696
#: The most levels a user message may nest (a message with no message field is one level;
#: a message-typed field adds its message's levels): deeper, a user call would take the
#: stack deeper than the firmware's own deepest path, which the RAM budget is measured at.
MAX_USER_LEVELS = (FIRMWARE_STACK - USER_CALL_STACK) // NANOPB_LEVEL_STACK
NANOPB_VERSION = "0.4.7"


@dataclass(frozen=True, slots=True)
class Method:
    number: int  # 1.. in declaration order (UserCall.method, UserReport.report)
    name: str  # the rpc's name
    snake: str  # its C and Python name
    request: str  # the request message's short name
    reply: str  # the reply (or report) message's short name
    report: bool  # server streaming: a report
    idempotent: bool
    commands: bool  # may drive outputs: refused while the failsafe or an interlock holds


@dataclass(frozen=True, slots=True)
class Service:
    proto: str  # the file name, "robot.proto"
    stem: str  # "robot"
    package: str
    name: str  # the service's name, "Robot"
    c_prefix: str  # nanopb's prefix of the file's types, "robot_"
    fingerprint: int
    methods: tuple[Method, ...]
    errors: tuple[tuple[str, int], ...]  # (value name, number) of <Service>Error, 0 left out
    error_enum: str  # "RobotError", or "" without one


@dataclass(frozen=True, slots=True)
class Generated:
    service: Service
    files: tuple[Path, ...]


def snake(name: str) -> str:
    """``SetSpeed`` -> ``set_speed``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", name).lower()


def camel(name: str) -> str:
    """``TOO_FAST`` -> ``TooFast``."""
    return "".join(part.capitalize() for part in name.lower().split("_") if part)


def fingerprint_of(descriptor_set: bytes) -> int:
    """CRC-32 of a FileDescriptorSet re-serialised deterministically, without source info."""
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(descriptor_set)
    for f in fds.file:
        f.ClearField("source_code_info")
    return zlib.crc32(fds.SerializeToString(deterministic=True)) & 0xFFFFFFFF


def _need(module: str) -> None:
    if importlib.util.find_spec(module) is None:
        raise ServiceGenError(
            f"the generator needs {module.split('.', maxsplit=1)[0]}: pip install 'protoduino[gen]'"
        )


def _run(cmd: list[str], cwd: Path) -> None:
    try:
        toolrun.run(cmd, cwd)
    except toolrun.ToolError as error:
        raise ServiceGenError(str(error)) from error


def _protoc(args: list[str], cwd: Path) -> None:
    try:
        toolrun.protoc(args, cwd)
    except toolrun.ToolError as error:
        raise ServiceGenError(str(error)) from error


def _mypy_plugin() -> str:
    exe = Path(sys.executable).parent / "protoc-gen-mypy"
    if not exe.exists():
        raise ServiceGenError("protoc-gen-mypy not found: pip install 'protoduino[gen]'")
    return str(exe)


def describe(proto: Path, descriptor_set: bytes) -> Service:
    """The service in ``proto`` as the generator needs it; refuses what it cannot carry."""
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(descriptor_set)
    (f,) = fds.file
    if f.dependency:
        raise ServiceGenError(
            f"{proto.name}: imports ({', '.join(f.dependency)}) are not supported: declare "
            "every message in the one file (a report's request: message Empty {})"
        )
    if len(f.service) != 1:
        raise ServiceGenError(f"{proto.name}: declare exactly one service, not {len(f.service)}")
    svc = f.service[0]
    level = descriptor_pb2.MethodOptions
    methods = []
    for number, m in enumerate(svc.method, start=1):
        if m.client_streaming:
            raise ServiceGenError(f"{proto.name}: rpc {m.name}: a client stream is not supported")
        idem = m.options.idempotency_level
        methods.append(
            Method(
                number=number,
                name=m.name,
                snake=snake(m.name),
                request=m.input_type.rsplit(".", 1)[-1],
                reply=m.output_type.rsplit(".", 1)[-1],
                report=m.server_streaming,
                idempotent=idem in (level.NO_SIDE_EFFECTS, level.IDEMPOTENT),
                commands=idem != level.NO_SIDE_EFFECTS,
            )
        )
    if not methods or len(methods) > 255:
        raise ServiceGenError(f"{proto.name}: service {svc.name} needs 1..255 rpcs")
    if sum(m.report for m in methods) > 8:
        raise ServiceGenError(f"{proto.name}: at most 8 report rpcs (pd_user.h)")
    error_enum = f"{svc.name}Error"
    errors: tuple[tuple[str, int], ...] = ()
    for enum in f.enum_type:
        if "Error" in enum.name and enum.name != error_enum:
            raise ServiceGenError(
                f"{proto.name}: enum {enum.name}: the handlers' error codes are the enum named "
                f"after the service, {error_enum} (<Service>Error); any other is not read, and "
                f"its codes would arrive as a plain UserError: rename it {error_enum}"
            )
        if enum.name == error_enum:
            errors = tuple((v.name, v.number) for v in enum.value if v.number != 0)
            if any(not 1 <= n <= 255 for _, n in errors):
                raise ServiceGenError(f"{proto.name}: {error_enum} values must be 0..255")
    package = f.package
    return Service(
        proto=proto.name,
        stem=proto.stem,
        package=package,
        name=svc.name,
        c_prefix=(package.replace(".", "_") + "_") if package else "",
        fingerprint=fingerprint_of(descriptor_set),
        methods=tuple(methods),
        errors=errors,
        error_enum=error_enum if errors else "",
    )


def with_package(options: str, package: str) -> str:
    """A ``.options`` file's text whose names may leave out the package.

    nanopb matches a line's name against the full one, package included
    (``tally.Add.name max_size:16``): a line without it (``Add.name max_size:16``)
    would match nothing, and its bound would be missing. Each such line is followed
    by its copy with the package, so both spellings work. Comment lines, wildcards
    (``*``) and lines that open or close a block comment stay as they are.
    """
    if not package:
        return options
    out = []
    for line in options.splitlines():
        out.append(line)
        name = line.split(None, 1)[0] if line.strip() else ""
        if (
            name
            and not name.startswith(("#", "//", "/*", "*", ".", f"{package}."))
            and "/*" not in line
            and "*/" not in line
        ):
            out.append(f"{package}.{line.lstrip()}")
    return "\n".join(out) + "\n"


def _levels(proto: Path, descriptor_set: bytes) -> dict[str, tuple[str, ...]]:
    """Each message's deepest chain of nested messages, by short name (a message with no
    message field: itself alone); refuses a message that contains itself."""
    from google.protobuf import descriptor_pb2

    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(descriptor_set)
    (f,) = fds.file
    types: dict[str, descriptor_pb2.DescriptorProto] = {}
    pending = [(f".{f.package}" if f.package else "", m) for m in f.message_type]
    while pending:
        scope, message = pending.pop(0)
        full = f"{scope}.{message.name}"
        types[full] = message
        pending += [(full, nested) for nested in message.nested_type]
    chains: dict[str, tuple[str, ...]] = {}

    def chain(full: str, seen: tuple[str, ...]) -> tuple[str, ...]:
        name = full.rsplit(".", 1)[-1]
        if full in seen:
            cycle = [each.rsplit(".", 1)[-1] for each in seen[seen.index(full) :]]
            raise ServiceGenError(
                f"{proto.name}: message {name} contains itself ({' > '.join([*cycle, name])}): "
                "a user message needs a bound on the device (no malloc)"
            )
        if full not in chains:
            inner = [
                chain(field.type_name, (*seen, full))
                for field in types[full].field
                if field.type == field.TYPE_MESSAGE
            ]
            chains[full] = (name, *max(inner, key=len, default=()))
        return chains[full]

    return {full.rsplit(".", 1)[-1]: chain(full, ()) for full in types}


def _check_levels(service: Service, levels: dict[str, tuple[str, ...]]) -> None:
    """Every message a method carries nests at most MAX_USER_LEVELS levels of messages."""
    for m in service.methods:
        for msg in (m.reply,) if m.report else (m.request, m.reply):
            nested = levels[msg]
            if len(nested) > MAX_USER_LEVELS:
                stack = USER_CALL_STACK + len(nested) * NANOPB_LEVEL_STACK
                raise ServiceGenError(
                    f"{service.proto}: message {msg} nests {len(nested)} levels of messages "
                    f"({' > '.join(nested)}), more than the {MAX_USER_LEVELS} a user message "
                    f"may have: nanopb takes about {NANOPB_LEVEL_STACK} B of the Uno's stack "
                    f"a level, so a call would take about {stack} B, deeper than the "
                    f"firmware's own deepest ({FIRMWARE_STACK} B; docs/services.md, *Limits*)"
                )


def _check_sizes(service: Service, header: str) -> None:
    """Every message a method carries has a nanopb bound within MAX_USER_BYTES."""
    for m in service.methods:
        for msg in (m.reply,) if m.report else (m.request, m.reply):
            found = re.search(rf"#define {service.c_prefix}{msg}_size\s+(\d+)", header)
            if found is None:
                raise ServiceGenError(
                    f"{service.proto}: message {msg} has no size bound: give each of its "
                    f"string, bytes and repeated fields a max_size / max_count in "
                    f"{service.stem}.options"
                )
            if int(found.group(1)) > MAX_USER_BYTES:
                raise ServiceGenError(
                    f"{service.proto}: message {msg} takes up to {found.group(1)} bytes on "
                    f"the wire, more than {MAX_USER_BYTES}: lower its bounds in "
                    f"{service.stem}.options"
                )


def generate(proto: Path, out: Path) -> Generated:
    """Write every file of the module docstring for ``proto`` into ``out``."""
    for module in ("grpc_tools.protoc", "nanopb.generator.nanopb_generator"):
        _need(module)
    proto = proto.resolve()
    if not proto.is_file():
        raise ServiceGenError(f"{proto}: no such file")
    out.mkdir(parents=True, exist_ok=True)
    out = out.resolve()
    src = proto.parent
    with tempfile.TemporaryDirectory() as tmp:
        desc = Path(tmp) / "user.desc"
        _protoc(["-I.", f"--descriptor_set_out={desc}", proto.name], src)
        service = describe(proto, desc.read_bytes())
        _check_levels(service, _levels(proto, desc.read_bytes()))
    _protoc(
        [
            "-I.",
            f"--python_out={out}",
            f"--mypy_out={out}",
            f"--plugin=protoc-gen-mypy={_mypy_plugin()}",
            proto.name,
        ],
        src,
    )
    nanopb = [sys.executable, "-W", "ignore", "-m", "nanopb.generator.nanopb_generator"]
    options = src / f"{proto.stem}.options"
    with tempfile.TemporaryDirectory() as tmp:
        if options.exists():
            packaged = Path(tmp) / options.name
            packaged.write_text(with_package(options.read_text(), service.package))
            nanopb += ["-f", str(packaged)]
        _run([*nanopb, "-I", str(src), "-D", str(out), "-q", str(proto)], src)
    header = (out / f"{proto.stem}.pb.h").read_text()
    _check_sizes(service, header)
    written = [
        out / f"{proto.stem}{suffix}" for suffix in (".pb.c", ".pb.h", "_pb2.py", "_pb2.pyi")
    ]
    for name, text in (
        (f"{service.stem}_service.h", c_header(service)),
        (f"{service.stem}_service.c", c_source(service)),
        (f"{service.stem}_client.py", python_client(service)),
    ):
        (out / name).write_text(text)
        written.append(out / name)
    return Generated(service, tuple(written))


# --- the firmware side ------------------------------------------------------


def _guard(service: Service) -> str:
    return f"{service.stem.upper()}_SERVICE_H"


def c_header(s: Service) -> str:
    p = s.c_prefix
    low = snake(s.name)
    lines = [
        f"/* Generated by `protoduino gen {s.proto}`. Do not edit. */",
        "/*",
        f" * The {s.name} service's firmware side (docs/services.md): implement every",
        " * function declared here in your own source; pd_user_service (the generated",
        " * .c) hands them the decoded messages. A handler returns 0 when done, or a",
        f" * value of {s.error_enum or 'your error enum'} (then nothing may have changed).",
        " */",
        f"#ifndef {_guard(s)}",
        f"#define {_guard(s)}",
        "",
        "#include <stdbool.h>",
        "#include <stdint.h>",
        "",
        '#include "pd_hal.h"',
        '#include "pd_user.h"',
        f'#include "{s.stem}.pb.h"',
        "",
        f"/* CRC-32 of {s.proto}'s FileDescriptorSet (DeviceInfo.user_fingerprint). */",
        f"#define {s.stem.upper()}_FINGERPRINT 0x{s.fingerprint:08X}UL",
        "",
    ]
    for m in s.methods:
        if m.report:
            lines += [
                f"/* rpc {m.name}: report {m.number}. Fill *report with the newest value; "
                "false: none. */",
                f"bool {low}_{m.snake}(pd_user_ctx_t *ctx, {p}{m.reply} *report);",
                f"/* A new value of {m.name}: sent when the line allows (newest wins). */",
                f"static inline void {low}_publish_{m.snake}(pd_user_ctx_t *ctx)",
                "{",
                f"    pd_user_publish(ctx, {m.number}u);",
                "}",
                "",
            ]
        else:
            lines += [
                f"/* rpc {m.name}: method {m.number}. */",
                f"uint8_t {low}_{m.snake}(pd_user_ctx_t *ctx, const {p}{m.request} *request,",
                f"    {p}{m.reply} *reply);",
                "",
            ]
    lines += [
        "/* A pin the service claimed (pd_user_claim), to its safe state: the failsafe, Stop",
        " * and interlocks call it (ctx->hal for the pins; it may publish a report). */",
        f"void {low}_safe(pd_user_ctx_t *ctx, uint8_t pin);",
        "/* A pin the service claimed, released (pd_user_release, Release, ReleaseAll, a new",
        " * session); the pin is no longer the service's here. */",
        f"void {low}_release(pd_user_ctx_t *ctx, uint8_t pin);",
        "/* Every pass of the device's main loop: work that takes time, in slices. */",
        f"void {low}_poll(pd_user_ctx_t *ctx, uint32_t now_ms);",
        "",
        f"#endif /* {_guard(s)} */",
        "",
    ]
    return "\n".join(lines)


def c_source(s: Service) -> str:
    p = s.c_prefix
    low = snake(s.name)
    calls = [m for m in s.methods if not m.report]
    lines = [
        f"/* Generated by `protoduino gen {s.proto}`. Do not edit. */",
        f'#include "{s.stem}_service.h"',
        "",
        "/* Every message fits the wire's 64 B (checked by the generator, and here). */",
    ]
    for m in s.methods:
        for msg in (m.reply,) if m.report else (m.request, m.reply):
            lines.append(
                f"typedef char {low}_{m.snake}_{msg}_fits"
                f"[({p}{msg}_size <= {MAX_USER_BYTES}) ? 1 : -1];"
            )
    lines += [
        "",
        "/* Scratch: the largest request, and the largest reply or report (static, no malloc). */",
        "static union {",
        "    uint8_t none;",
        *[f"    {p}{m.request} m{m.number};" for m in calls],
        "} request_buf;",
        "static union {",
        "    uint8_t none;",
        *[f"    {p}{m.reply} m{m.number};" for m in s.methods],
        "} reply_buf;",
        "",
    ]
    for m in s.methods:
        if m.report:
            lines += [
                f"static bool report_{m.snake}(pd_user_ctx_t *ctx, void *report)",
                "{",
                f"    return {low}_{m.snake}(ctx, ({p}{m.reply} *)report);",
                "}",
                "",
            ]
        else:
            lines += [
                f"static uint8_t call_{m.snake}(pd_user_ctx_t *ctx, const void *request, "
                "void *reply)",
                "{",
                f"    return {low}_{m.snake}(ctx, (const {p}{m.request} *)request, "
                f"({p}{m.reply} *)reply);",
                "}",
                "",
            ]
    lines.append("static const pd_user_method_t methods[] = {")
    for m in s.methods:
        flags = (
            " | ".join(
                f
                for f, on in (
                    ("PD_USER_IDEMPOTENT", m.idempotent),
                    ("PD_USER_COMMANDS", m.commands),
                )
                if on
            )
            or "0"
        )
        if m.report:
            lines.append(
                f"    {{NULL, {p}{m.reply}_fields, NULL, report_{m.snake}, 0}}, /* {m.name} */"
            )
        else:
            lines.append(
                f"    {{{p}{m.request}_fields, {p}{m.reply}_fields, call_{m.snake}, NULL, "
                f"{flags}}}, /* {m.name} */"
            )
    lines += [
        "};",
        "",
        "const pd_user_service_t pd_user_service = {",
        f"    {s.stem.upper()}_FINGERPRINT,",
        f"    {len(s.methods)}u,",
        "    methods,",
        "    &request_buf,",
        "    sizeof(request_buf),",
        "    &reply_buf,",
        "    sizeof(reply_buf),",
        f"    {low}_safe,",
        f"    {low}_release,",
        f"    {low}_poll,",
        "};",
        "",
    ]
    return "\n".join(lines)


# --- the host side ---------------------------------------------------------


def _error_class(s: Service, value: str) -> str:
    prefix = snake(s.error_enum).upper() + "_"
    short = value[len(prefix) :] if value.startswith(prefix) else value
    name = f"{camel(short)}Error"
    # Never a builtin's name (VALUE -> ValueError): the service's own then.
    return f"{s.name}{name}" if hasattr(builtins, name) else name


def python_client(s: Service) -> str:
    base = f"{s.name}Error"
    lines = [
        f'"""The {s.package + "." if s.package else ""}{s.name} service\'s client, generated by '
        f"`protoduino gen {s.proto}`. Do not edit.",
        "",
        f"Attach it to an open board: ``{snake(s.name)} = {s.name}(board)`` (or",
        f"``Async{s.name}(aio_board)``); it checks the firmware carries this service.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        "from collections.abc import Callable",
        "from concurrent.futures import Future",
        "from typing import ClassVar",
        "",
        f"import {s.stem}_pb2 as pb",
        "from protoduino import aio",
        "from protoduino.errors import UserError",
        "from protoduino.services import (",
        "    REPORT_BUFFER,",
        "    AsyncServiceClient,",
        "    Report,",
        "    ReportStream,",
        "    ServiceClient,",
        ")",
        "",
        f'PROTO = "{s.proto}"',
        f"FINGERPRINT = 0x{s.fingerprint:08X}",
        "",
        "",
        f"class {base}(UserError):",
        f'    """A {s.name} handler refused the call (its code: ``code``)."""',
        "",
        '    NAME: ClassVar[str] = ""',
        "",
    ]
    for value, number in s.errors:
        lines += [
            "",
            f"class {_error_class(s, value)}({base}):",
            f'    """{s.error_enum}.{value} ({number})."""',
            "",
            f'    NAME = "{value}"',
            "",
        ]
    lines += [
        "",
        "ERRORS: dict[int, type[UserError]] = {",
        *[f"    {number}: {_error_class(s, value)}," for value, number in s.errors],
        "}",
        "",
        "",
        f"class {s.name}(ServiceClient):",
        f'    """{s.name}\'s rpcs on a :class:`protoduino.Board`."""',
        "",
        "    PROTO = PROTO",
        "    FINGERPRINT = FINGERPRINT",
        "    ERRORS = ERRORS",
    ]
    for m in s.methods:
        if m.report:
            lines += [
                "",
                f"    def on_{m.snake}(",
                f"        self, callback: Callable[[Report[pb.{m.reply}]], None]",
                "    ) -> Callable[[], None]:",
                f'        """Call ``callback`` (event thread) with each newest {m.name} report; '
                'returns its remover."""',
                f"        return self._on_report({m.number}, pb.{m.reply}, callback)",
                "",
                f"    def {m.snake}(self) -> Report[pb.{m.reply}] | None:",
                f'        """The newest {m.name} report received (None: none yet)."""',
                f"        return self._latest({m.number}, pb.{m.reply})",
            ]
        else:
            lines += [
                "",
                f"    def {m.snake}(self, request: pb.{m.request}) -> pb.{m.reply}:",
                f'        """rpc {m.name}: returns once the device answered; raises its errors."""',
                "        return self._call(",
                f'            {m.number}, "{m.name}", request, pb.{m.request}, pb.{m.reply}',
                "        )",
                "",
                f"    def submit_{m.snake}(self, request: pb.{m.request}) -> Future[pb.{m.reply}]:",
                f'        """rpc {m.name} without waiting: a future of the reply (or of its '
                'error)."""',
                "        return self._submit(",
                f'            {m.number}, "{m.name}", request, pb.{m.request}, pb.{m.reply}',
                "        )",
            ]
    lines += [
        "",
        "",
        f"class Async{s.name}(AsyncServiceClient[{s.name}]):",
        f'    """{s.name}\'s rpcs on a :class:`protoduino.aio.Board`."""',
        "",
        f"    SYNC = {s.name}",
        "",
        "    def __init__(self, board: aio.Board) -> None:",
        "        super().__init__(board)",
    ]
    for m in s.methods:
        if m.report:
            lines += [
                "",
                f"    def {m.snake}_reports(",
                "        self, maxsize: int = REPORT_BUFFER",
                f"    ) -> ReportStream[pb.{m.reply}]:",
                f'        """An async iterator of the {m.name} reports from now (newest wins)."""',
                f"        return self._stream({m.number}, pb.{m.reply}, maxsize)",
            ]
        else:
            lines += [
                "",
                f"    async def {m.snake}(self, request: pb.{m.request}) -> pb.{m.reply}:",
                f'        """rpc {m.name}, awaited."""',
                f"        return await self._wait(self.sync.submit_{m.snake}(request))",
            ]
    lines.append("")
    return "\n".join(lines)
