"""The type stubs (python/sawlink.pyi) in step with the module: every public name the module
exports is stubbed, and every public method and attribute of the board's classes is in its
class's stub. Read with Python's own parser, compared with what the built module has."""

import ast
import inspect

import sawlink
from conftest import REPO

STUB = ast.parse((REPO / "python" / "sawlink.pyi").read_text())


def stubbed():
    """Top-level names of the stub, and each class's member names."""
    top, members = set(), {}
    for node in STUB.body:
        if isinstance(node, ast.ClassDef):
            top.add(node.name)
            names = set()
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    names.add(item.name)
                elif isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    names.add(item.target.id)
            members[node.name] = names
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            top.add(node.target.id)
    return top, members


def test_every_public_name_is_stubbed():
    top, _ = stubbed()
    # (`sawlink.sawlink` is the extension module itself, which maturin's package re-exports.)
    public = {n for n in dir(sawlink)
              if not n.startswith("_") and not inspect.ismodule(getattr(sawlink, n))}
    assert public - top == set()


def test_the_board_classes_members_are_stubbed():
    _, members = stubbed()
    for cls in (sawlink.Board, sawlink.Record, sawlink.Record2d, sawlink.Recording,
                sawlink.Stream):
        public = {n for n, _ in inspect.getmembers(cls) if not n.startswith("_")}
        assert public - members[cls.__name__] == set(), cls.__name__
