"""What produced a result: the toolkit's version, library versions and the git commit."""
from __future__ import annotations

import ast
import functools
import hashlib
import importlib
import platform
import subprocess
from pathlib import Path

from common import __version__

REPO = Path(__file__).resolve().parent.parent


def git_commit() -> str | None:
    """HEAD of the repository this package runs from (None outside a git checkout)."""
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, timeout=5)
        return r.stdout.strip() or None
    except OSError:
        return None


def versions(*modules: str, **extra: str) -> dict[str, str]:
    """{toolkit, python, numpy, each named module's __version__, **extra}."""
    import numpy as np

    out = {"toolkit": __version__, "python": platform.python_version(), "numpy": np.__version__}
    for name in modules:
        out[name] = importlib.import_module(name).__version__
    return {**out, **extra}


# What a benchmark job runs: its driver (training, scoring, the row) and, per method, the module that
# registers it. The code version is the import closure of these entries inside the checkout (every
# `import` and `from ... import`, at module level or inside a function, followed to the files of the
# checkout's own packages; third-party packages are recorded as versions, not hashed), so a module a
# job reads through (the event reader in eventio/, say) cannot drift out of it, and a command line the
# job never imports is not in it.
JOB_ENTRY = "benchmark.job_run"


def _module_file(root: Path, name: str) -> Path | None:
    """The file of module `name` under `root` (a package's __init__.py), None outside the checkout."""
    base = root.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _imported_names(tree: ast.AST, module: str, is_package: bool) -> set[str]:
    """Every module name `tree` imports: `import a.b` -> a, a.b; `from a import b` -> a, a.b (b may be a
    submodule); relative imports resolved against `module`; importlib.import_module("a.b") literals."""
    names: set[str] = set()
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - node.level + 1]
                base = ".".join(p for p in parts + ([node.module] if node.module else []) if p)
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            names.add(node.args[0].value)
    out = set()
    for name in names:              # importing a.b.c runs a/__init__ and a/b/__init__ too
        parts = name.split(".")
        out.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return out


def import_closure(entries: tuple[str, ...], root: Path = REPO) -> dict[str, Path]:
    """{module name: file} of every checkout module reachable from `entries` by imports (the entries
    included), sorted by name."""
    seen: dict[str, Path] = {}
    todo = list(entries)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        path = _module_file(root, name)
        if path is None:
            continue
        seen[name] = path
        todo.extend(_parsed(path, name)[1] - seen.keys())
    return dict(sorted(seen.items()))


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
                node.body = node.body[1:] or [ast.Pass()]
    return tree


def _parsed(path: Path, module: str) -> tuple[str, frozenset[str]]:
    """(normalised digest, imported module names) of one source file, parsed once per version of it."""
    st = path.stat()
    return _parse(path, module, (st.st_size, st.st_mtime_ns, st.st_ino))


@functools.lru_cache(maxsize=4096)
def _parse(path: Path, module: str, stamp: tuple[int, int, int]) -> tuple[str, frozenset[str]]:
    tree = ast.parse(path.read_bytes(), filename=str(path))
    imports = frozenset(_imported_names(tree, module, path.name == "__init__.py"))
    return normalised_tree_digest(tree), imports


def normalised_tree_digest(tree: ast.AST) -> str:
    """SHA-256 of a syntax tree without docstrings, line numbers (hence comments and formatting, which
    the parser drops): the same for two sources that run the same statements."""
    tree = _strip_docstrings(tree)
    return hashlib.sha256(ast.dump(tree, annotate_fields=False, include_attributes=False).encode()).hexdigest()


def normalised_digest(path: Path) -> str:
    """normalised_tree_digest of a source file."""
    return normalised_tree_digest(ast.parse(Path(path).read_bytes(), filename=str(path)))


def code_version(root: Path = REPO, entries: tuple[str, ...] = (JOB_ENTRY,)) -> str:
    """SHA-256 (16 hex digits) of the normalised sources (normalised_digest) of import_closure(entries)
    under `root`, by module name: changes when a statement changes in any module a job imports,
    committed or not, and not for a comment, a docstring or reformatting; the same for a git checkout
    and an installed copy of the same code (which has no commit)."""
    root = Path(root)
    h = hashlib.sha256()
    for name, path in import_closure(tuple(entries), root).items():
        h.update(name.encode() + b"\0" + _parsed(path, name)[0].encode() + b"\0")
    return h.hexdigest()[:16]
