"""The documented surface: names, docstrings, and the stub matching the extension."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import dyfos
from dyfos import _dyfos, ros


def test_every_public_name_exists_and_is_documented() -> None:
    for module in (dyfos, ros):
        assert module.__doc__
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.isclass(obj) or inspect.isfunction(obj):
                assert obj.__doc__, f"{module.__name__}.{name} has no docstring"
    for name, member in inspect.getmembers(dyfos.Client):
        if not name.startswith("_") and callable(member):
            assert member.__doc__, f"Client.{name} has no docstring"


def test_the_stub_names_what_the_extension_has() -> None:
    stub = ast.parse((Path(dyfos.__file__).parent / "_dyfos.pyi").read_text())
    for node in stub.body:
        if isinstance(node, ast.ClassDef):
            cls = getattr(_dyfos, node.name)
            declared = {n.name for n in node.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("__")}
            actual = {n for n in dir(cls) if not n.startswith("__")}
            assert declared == actual, node.name
        elif isinstance(node, ast.FunctionDef):
            assert callable(getattr(_dyfos, node.name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            assert hasattr(_dyfos, node.target.id)
    assert (Path(dyfos.__file__).parent / "py.typed").exists()


def test_the_documented_signatures() -> None:
    """The documented names and defaults stay as they are (others script against them)."""
    sig = inspect.signature(dyfos.Client.rendezvous)
    expected = {
        "algorithm": "dyfos",
        "seed": 0,
        "params": None,
        "budget": None,
        "deadline": None,
        "expected_version": None,
        "deltas": None,
    }
    assert list(sig.parameters)[:4] == ["self", "map_id", "mean", "cov"]
    for name, default in expected.items():
        assert sig.parameters[name].default == default, name
    init = inspect.signature(dyfos.Client.__init__)
    assert [(p, init.parameters[p].default) for p in ("prefix", "domain", "timeout")] == [
        ("prefix", "dyfos/"),
        ("domain", None),
        ("timeout", 1.0),
    ]
    assert issubclass(dyfos.DyfosTimeoutError, TimeoutError)
    for family in (
        dyfos.UnknownMapError,
        dyfos.MapVersionMismatchError,
        dyfos.InvalidRequestError,
        dyfos.NoFeasiblePoseError,
        dyfos.DeadlineExceededError,
        dyfos.BusyError,
        dyfos.DaemonGoneError,
        dyfos.DyfosTimeoutError,
    ):
        assert issubclass(family, dyfos.DyfosError)
