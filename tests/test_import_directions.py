"""Dependencies point one way (HOUSE.md): read every module's imports with `ast` (those inside
functions too) and check who imports whom; the light shared modules load no numba."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(source: str, module: str) -> set[str]:
    """The absolute names of the modules `source` (the text of `module`) imports."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the importing package
                base = module.split(".")[: -node.level]
                found.add(".".join([*base, node.module] if node.module else base))
            else:
                found.add(node.module or "")
    return found


def edges(package: str) -> set[tuple[str, str]]:
    """(importer, imported) for every module of `package`."""
    out = set()
    for path in sorted((ROOT / package).rglob("*.py")):
        module = _module(path)
        out.update((module, name) for name in imports_of(path.read_text(), module))
    return out


def _top(name: str) -> str:
    return name.split(".", 1)[0]


def test_imports_of_finds_nested_and_relative_imports():
    source = "import a.b\nfrom c import d\ndef f():\n    from .e import g\n    from . import h\n"
    assert imports_of(source, "pkg.sub.mod") == {"a.b", "c", "pkg.sub.e", "pkg.sub"}


def test_backend_does_not_import_frontend():
    # the app that mounts the dashboard beside the API is `mapqual.app`, above both
    wrong = {(a, b) for a, b in edges("backend") if _top(b) == "frontend"}
    assert wrong == set()


def test_worker_imports_neither_backend_nor_frontend():
    # the Celery task calls the run host the backend registers (`worker.tasks.serve`)
    wrong = {(a, b) for a, b in edges("worker") if _top(b) in ("backend", "frontend")}
    assert wrong == set()


def test_the_shared_vocabularies_import_only_the_standard_library_and_numpy():
    for name in ("status", "live_wire"):
        path = ROOT / "worker" / f"{name}.py"
        tree = ast.parse(path.read_text())
        runtime = set()
        for node in tree.body:  # module level, outside `if TYPE_CHECKING:`
            if isinstance(node, ast.Import):
                runtime.update(_top(a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                runtime.add(_top(node.module or ""))
        assert runtime <= {"__future__", "base64", "enum", "typing", "zlib", "numpy"}, name


def test_the_shared_vocabularies_load_no_numba_nor_database():
    heavy = ("numba", "sqlalchemy", "backend", "frontend")
    code = (
        "import sys, worker.status, worker.live_wire; "
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_the_services_speak_no_http():
    # typed errors (backend/services/errors.py), mapped to HTTP in backend/api/errors.py alone
    wrong = {
        (a, b)
        for a, b in edges("backend")
        if a.startswith(("backend.services", "backend.store", "backend.core.queue"))
        and _top(b) in ("fastapi", "starlette")
    }
    assert wrong == set()


def test_the_cli_reaches_the_database_through_the_services():
    # `mapqual users|runs|score|run` call backend.services; the CLI holds no session, model or
    # store function of its own (the settings and `mapqual db upgrade` aside)
    allowed = ("backend.services", "backend.core.config", "backend.db.migrate")
    wrong = {
        (a, b)
        for a, b in edges("mapqual/cli")
        if _top(b) == "backend" and not (b in allowed or b.startswith(f"{allowed[0]}."))
    }
    assert wrong == set()


def test_the_dashboard_reads_and_writes_through_the_services():
    # the pages call backend.services for every read and write (the models' classes, the
    # API's request dependencies and schemas aside): no store function of their own
    wrong = {(a, b) for a, b in edges("frontend/dashboard") if b.startswith("backend.store")}
    assert wrong == set()
