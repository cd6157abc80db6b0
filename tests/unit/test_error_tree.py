"""Every error the package raises is in the tree of protoduino.errors (issue 20, item 13).

docs/architecture.md promises that catching ``ProtoduinoError`` catches everything protoduino
raises. A builtin ValueError or TypeError raised by the package would escape it: the AST walk
below finds every ``raise`` of one, so a new bare one fails here rather than in an application.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import protoduino
import protoduino.errors

PACKAGE = Path(protoduino.__file__).parent
#: Builtins that must be raised as their protoduino subclass (ArgumentError, ...).
BUILTINS = {"ValueError", "TypeError"}
#: Exception classes of the package outside the tree, each caught inside it (checked below):
#: toolrun is standard library only on purpose (codegen loads it by its path, without the
#: package) and servicegen maps its error to ServiceGenError; capturereader's is private.
INTERNAL = {"protoduino.toolrun.ToolError", "protoduino.capturereader._LineError"}


def _raised_name(node: ast.Raise) -> str | None:
    exc = node.exc
    if isinstance(exc, ast.Call):
        exc = exc.func
    return exc.id if isinstance(exc, ast.Name) else None


def _bare_raises() -> list[str]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_generated" in path.parts:
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Raise) and _raised_name(node) in BUILTINS:
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    return found


def test_the_walk_finds_a_bare_raise(tmp_path: Path) -> None:
    """The walk itself: it sees ``raise ValueError(...)`` and ``raise TypeError``."""
    source = "def f(x):\n    if x:\n        raise ValueError('no')\n    raise TypeError\n"
    raises = sorted(
        (n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Raise)),
        key=lambda n: n.lineno,
    )
    assert [_raised_name(n) for n in raises] == ["ValueError", "TypeError"]


def test_no_builtin_value_or_type_error_is_raised_by_the_package() -> None:
    assert _bare_raises() == []


def test_argument_errors_are_the_builtins_too() -> None:
    assert issubclass(protoduino.ArgumentError, ValueError)
    assert issubclass(protoduino.ArgumentError, protoduino.ProtoduinoError)
    assert issubclass(protoduino.ArgumentTypeError, TypeError)
    assert issubclass(protoduino.ArgumentTypeError, protoduino.ProtoduinoError)


def test_every_error_of_the_tree_is_importable_from_protoduino() -> None:
    tree = {
        name
        for name, cls in inspect.getmembers(protoduino.errors, inspect.isclass)
        if issubclass(cls, protoduino.ProtoduinoError)
    }
    assert {"SimControlError", "BuildError", "FlashError", "CaptureError"} <= tree
    assert {"ServiceGenError", "ConfigError", "ExtraMissingError", "BadCommandError"} <= tree
    for name in tree:
        assert getattr(protoduino, name) is getattr(protoduino.errors, name), name
        assert name in protoduino.__all__, name


def _drawn(text: str) -> set[str]:
    """The classes a drawing of the tree names (``+-- Name``), and its root."""
    return set(re.findall(r"\+-- (\w+)", text)) | {"ProtoduinoError"}


def test_the_docstring_tree_names_every_error() -> None:
    """The tree drawn in errors.py (and docs/api.md) lists every class, and nothing else."""
    tree = {
        name
        for name, cls in inspect.getmembers(protoduino.errors, inspect.isclass)
        if issubclass(cls, protoduino.ProtoduinoError)
    }
    api = (PACKAGE.parents[1] / "docs" / "api.md").read_text()
    start = api.index("\nProtoduinoError\n", api.index("## Errors"))
    drawing = api[start : api.index("```", start)]
    assert _drawn(protoduino.errors.__doc__ or "") == tree
    assert _drawn(drawing) == tree


def _exception_classes() -> dict[str, type[BaseException]]:
    """Every exception class a module of the package defines, by its qualified name."""
    found: dict[str, type[BaseException]] = {}
    for info in pkgutil.walk_packages(protoduino.__path__, "protoduino."):
        module = importlib.import_module(info.name)
        for name, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, BaseException) and cls.__module__ == module.__name__:
                found[f"{module.__name__}.{name}"] = cls
    return found


def test_every_exception_class_of_the_package_is_in_the_tree() -> None:
    """A class of its own outside the tree (``class BadCommandError(ValueError)``) escapes
    ``except ProtoduinoError`` as a bare builtin would; the walk above cannot see it."""
    classes = _exception_classes()
    assert "protoduino.errors.ArgumentError" in classes  # the walk reads the package
    outside = {
        name
        for name, cls in classes.items()
        if not issubclass(cls, protoduino.ProtoduinoError) and name not in INTERNAL
    }
    assert outside == set()
    for name, cls in classes.items():
        if issubclass(cls, protoduino.ProtoduinoError):
            assert cls.__module__ == "protoduino.errors", f"{name}: define it in errors.py"


def test_the_internal_exceptions_are_caught_inside_the_package() -> None:
    caught = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ExceptHandler) and node.type is not None:
                caught.add(ast.unparse(node.type).rsplit(".", 1)[-1])
    for name in INTERNAL:
        assert name.rsplit(".", 1)[-1] in caught, name
