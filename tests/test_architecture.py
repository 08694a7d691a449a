"""The package layering of docs/architecture.md, read from the code's own imports."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = {"common": 0, "simulator": 1, "blender_scenes": 1, "datagen": 2, "e2vid": 2, "recon": 3,
          "benchmark": 4, "viewer": 4, "e4dgs": 5}


def package_imports() -> dict[str, set[tuple[str, str]]]:
    """{package: {(imported package, file)}} for imports of other project packages (any depth)."""
    found = {p: set() for p in LAYERS}
    for pkg in LAYERS:
        for f in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text(), str(f))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.split(".")[0]
                    if top in LAYERS and top != pkg:
                        found[pkg].add((top, str(f.relative_to(ROOT))))
    return found


def test_every_import_between_packages_points_down():
    bad = sorted(f"{src} imports {dst} (layer {LAYERS[pkg]} -> {LAYERS[dst]})"
                 for pkg, edges in package_imports().items() for dst, src in edges if LAYERS[dst] >= LAYERS[pkg])
    assert bad == []


def test_the_layers_are_documented_as_tested():
    text = (ROOT / "docs" / "architecture.md").read_text()
    for pkg, layer in LAYERS.items():
        assert f"| {layer} | `{pkg}/` |" in text, pkg


def _importers_of(module: str) -> set[str]:
    """Files (relative to the repository) with an `import module` / `from module ...` anywhere in them."""
    users = set()
    for pkg in LAYERS:
        for f in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text())):
                if isinstance(node, ast.Import) and any(a.name.split(".")[0] == module for a in node.names):
                    users.add(str(f.relative_to(ROOT)))
                elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == module:
                    users.add(str(f.relative_to(ROOT)))
    return users


def test_only_the_render_packages_import_bpy():
    users = {f.split("/")[0] for f in _importers_of("bpy")}
    assert users <= {"datagen", "blender_scenes"}, users


def test_only_the_task_pool_imports_ray():
    assert _importers_of("ray") == {"common/taskpool.py"}     # and only inside a function (tests/test_ray.py)
