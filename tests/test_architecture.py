"""The package layering of docs/design/architecture.md, read from the code's own imports."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = {"common": 0, "eventio": 1, "blender_scenes": 1, "simulator": 2, "scene_format": 3, "e2vid": 3,
          "datagen": 4, "recon": 5, "benchmark": 6, "viewer": 6, "e4dgs": 7, "tools": 8}


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


def test_reconstruction_and_the_viewer_never_import_the_generator():
    """They read scene folders through scene_format; the Blender render loop is not theirs to import."""
    edges = package_imports()
    assert sorted(src for dst, src in edges["recon"] | edges["viewer"] if dst in ("datagen", "blender_scenes")) == []


def test_reconstruction_reads_the_scene_description_not_the_generator_config():
    """recon reads `dataset.scene` (a frozen SceneDescription); `dataset.config` is the generator's."""
    users = [str(f.relative_to(ROOT)) for f in (ROOT / "recon").rglob("*.py")
             if "SceneConfig" in f.read_text() or ".config.lighting" in f.read_text() or "dataset.config" in f.read_text()]
    assert users == []


def test_the_layers_are_documented_as_tested():
    text = (ROOT / "docs" / "design" / "architecture.md").read_text()
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
    assert _importers_of("ray") == {"common/taskpool.py"}     # and only inside a function (tests/benchmark/test_ray.py)


def module_graph() -> dict[str, set[str]]:
    """{module: modules of the project it imports} from every import statement in every file (also
    those inside functions or under TYPE_CHECKING: a circle there is still a circle of ideas)."""
    mods = {}
    for pkg in LAYERS:
        for f in (ROOT / pkg).rglob("*.py"):
            name = ".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            mods[name] = f

    def owner(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph = {m: set() for m in mods}
    for m, f in mods.items():
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            for n in names:
                target = owner(n)
                if target and target != m and not m.startswith(target + "."):   # a package's own __init__
                    graph[m].add(target)
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                group = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    group.append(w)
                    if w == v:
                        break
                if len(group) > 1:
                    out.append(sorted(group))
    return out


def test_the_circle_finder_finds_a_circle():
    assert import_circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_circles({"a": {"b"}, "b": set()}) == []


def test_no_two_files_import_each_other_even_indirectly():
    assert import_circles(module_graph()) == []


def test_the_tests_mirror_the_packages():
    """tests/<package>/ holds the tests of one package (tests/e4dgs/: the command line, end to end);
    tests/fixtures/ the test-only inputs (configs the toolkit does not ship); beside them, the tests of
    the whole tree: its layering and its docs."""
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and not p.name.startswith((".", "__"))}
    assert folders and folders <= set(LAYERS) | {"fixtures"}, sorted(folders - set(LAYERS))
    assert sorted(p.name for p in (ROOT / "tests").glob("test_*.py")) == ["test_architecture.py", "test_docs.py"]


def test_reading_a_scene_or_drawing_events_loads_no_simulator_kernel():
    """A scene's config holds a sensor's config, and the viewer draws events: neither imports the
    simulator's numba kernels (simulator/__init__ loads them on first use of EventSimulator)."""
    import subprocess
    import sys

    code = ("import sys, scene_format, scene_format.reader, recon.event_windows, viewer, datagen.preview\n"
            "loaded = [m for m in ('simulator.simulator', 'simulator.kernels', 'simulator.kernel_ref', 'simulator.noise',"
            " 'simulator.readout') if m in sys.modules]\n"
            "assert not loaded, loaded\n"
            "from simulator import EventSimulator\n"
            "assert 'simulator.kernels' in sys.modules\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
