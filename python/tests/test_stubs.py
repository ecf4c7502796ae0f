"""The hand-kept stubs describe the extension: every public name and method, no more."""

import ast
import inspect
from pathlib import Path

import backdrive_rig
from backdrive_rig import _native


def stub_tree():
    path = Path(backdrive_rig.__file__).with_name("_native.pyi")
    return ast.parse(path.read_text())


def test_stubs_ship_with_the_package():
    here = Path(backdrive_rig.__file__).parent
    assert (here / "_native.pyi").exists()
    assert (here / "py.typed").exists()


def test_every_native_name_is_in_the_stub_and_back():
    tree = stub_tree()
    stubbed = set()
    methods = {}
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            stubbed.add(node.name)
        if isinstance(node, ast.ClassDef):
            methods[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        if isinstance(node, ast.AnnAssign):
            stubbed.add(node.target.id)
    native = {n for n in dir(_native) if not n.startswith("__")}
    assert native <= stubbed, native - stubbed
    for cls in ("NativeRig", "NativeRecording", "NativeReleaseStatus"):
        real = {n for n, _ in inspect.getmembers(getattr(_native, cls)) if not n.startswith("_")}
        stub = {n for n in methods[cls] if not n.startswith("_")}
        assert real == stub, (cls, real ^ stub)


def test_every_public_item_has_a_docstring():
    for name in backdrive_rig.__all__:
        obj = getattr(backdrive_rig, name)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            assert obj.__doc__, name
            for m, f in inspect.getmembers(obj, inspect.isfunction):
                if not m.startswith("_"):
                    assert f.__doc__, f"{name}.{m}"
