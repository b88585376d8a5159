"""The packages are layers and every import runs downward, including imports inside functions.

A module may import its own layer and the layers below it. The package facades
(``hybrid``, ``identification``, ``physics``) re-export names for users and sit on top of
what they re-export: a module may import a facade only from a layer strictly above it
(``physics.virtual`` may use ``physics``; ``identification._identify`` may not use
``identification``, which re-exports it).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: Lowest first. A module belongs to the longest prefix that names it.
LAYERS = (
    ("physics.data", "hybrid.data", "hybrid.datasets", "hybrid._version"),  # trajectories, loaders, fetching, atomic writes; the version
    ("physics",),                                 # blocks, Series, the torch path of a Series
    ("physics.virtual", "hybrid.virtual"),        # the virtual catheter (simulated measurements)
    ("identification",),                          # fitting
    ("identification.discovery",),                # the discrepancy workflow
    ("hybrid.networks",),                         # network specs, their torch modules and CasADi steps
    ("hybrid.learning",),                         # learned models, training, checkpoints
    ("hybrid.peers",),                            # other tools' models (ARX, NARX, SUBNET) under our contract
    ("hybrid.intervals",),                        # conformal intervals, distance to the data (any model)
    ("hybrid.models",),                           # hybrids
    ("hybrid.export",),                           # CasADi export, C code, loading any saved model
    ("hybrid.control",),                          # MPC, adjoint SQP, closed loop, model inverse
    ("hybrid.experiments",),                      # reproduce, compare, ablations, plots
    ("hybrid.cli",),                              # the hyst command line
)
#: The layer of each facade: the highest layer it re-exports.
FACADES = {"physics": 1, "identification": 4, "hybrid": len(LAYERS) - 1}


def layer_of(module: str) -> int:
    if module in FACADES:
        return FACADES[module]
    best, level = "", None
    for i, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > len(best):
                best, level = prefix, i
    if level is None:
        raise AssertionError(f"module {module} is in no declared layer; add it to LAYERS")
    return level


def modules():
    for top in ("physics", "identification", "hybrid"):
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            is_pkg = parts[-1] == "__init__"
            yield (".".join(parts[:-1]) if is_pkg else ".".join(parts)), is_pkg, path


def imports(module: str, is_pkg: bool, path: Path):
    """Project modules that ``path`` imports anywhere in its body, with line numbers."""
    package = module.split(".") if is_pkg else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [f"{target}.{a.name}" for a in node.names]
            yield node.lineno, target, names
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, []


def _project(name: str) -> bool:
    return name.split(".")[0] in ("physics", "identification", "hybrid")


def test_every_import_runs_downward():
    known = {m for m, _, _ in modules()}
    upward = []
    for module, is_pkg, path in modules():
        own = layer_of(module)
        for line, target, names in imports(module, is_pkg, path):
            if not _project(target):
                continue
            # `from pkg import submodule` imports the submodule
            targets = [n for n in names if n in known] or [target]
            for t in targets:
                if layer_of(t) > own or (t in FACADES and layer_of(t) == own):
                    upward.append(f"{path.relative_to(ROOT)}:{line} imports {t}")
    assert not upward, "imports that run upward:\n" + "\n".join(upward)


BLOCKER = textwrap.dedent("""
    import importlib.abc, sys
    BLOCKED = {"torch", "torchdiffeq", "dask", "distributed", "pysindy", "sklearn"}
    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r} (blocked for this test)", name=name)
    sys.meta_path.insert(0, Block())
""")


def test_physics_and_identification_work_without_the_optional_extras():
    script = BLOCKER + textwrap.dedent("""
        import numpy as np
        import physics, identification
        from physics import Series
        from physics.data import Trajectory
        from physics.virtual import VirtualCatheter, DecayingSinusoid
        from identification import identify
        truth = Series.from_spec("lag+linear", dt=0.04)
        truth.set_params(**{"lag.time_constant_s": 0.2, "linear.gain": 2.0, "linear.offset": 1.0})
        t = np.arange(400) * 0.04
        u = 1.0 + np.sin(2 * np.pi * 0.3 * t)
        fit = identify(Series.from_spec("lag+linear", dt=0.04), [Trajectory(t, u, truth.simulate(u))])
        assert abs(fit.parameters["lag.time_constant_s"] - 0.2) < 1e-4, fit.parameters
        VirtualCatheter(seed=0).run(DecayingSinusoid(0.5, "mid"))
        for name in ("torch", "torchdiffeq", "dask", "pysindy", "sklearn"):
            assert name not in sys.modules, name
        print("ok")
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr[-2000:]


def test_a_command_that_needs_a_missing_extra_names_the_extra(tmp_path):
    csv = tmp_path / "run.csv"
    t = [i * 0.04 for i in range(200)]
    csv.write_text("time,u,y\n" + "".join(f"{a},{(a % 2)},{2 * (a % 2)}\n" for a in t))
    script = BLOCKER + textwrap.dedent(f"""
        from hybrid.cli import main
        sys.exit(main(["train", {str(csv)!r}, "--model", "fnn", "--epochs", "1",
                       "--out", {str(tmp_path / "m.pt")!r}]))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "needs torch" in proc.stderr and "pip install 'hysteresis-hybrid[learning]'" in proc.stderr, proc.stderr
    assert not (tmp_path / "m.pt").exists()


def _import_graph() -> dict[str, set[str]]:
    known = {m for m, _, _ in modules()}
    graph: dict[str, set[str]] = {}
    for module, is_pkg, path in modules():
        for _, target, names in imports(module, is_pkg, path):
            if _project(target):
                graph.setdefault(module, set()).update(t for t in ([n for n in names if n in known] or [target])
                                                       if t != module)
    return graph


@pytest.mark.parametrize("layer", ["physics", "physics.data", "physics.virtual", "identification", "hybrid.networks",
                                   "hybrid.learning", "hybrid.models", "hybrid.export", "hybrid.control",
                                   "hybrid.experiments", "hybrid.cli"])
def test_no_import_circles_within_a_layer(layer):
    """Within these layers an import never leads back to the importer (plots import from what they plot)."""
    graph = _import_graph()

    def reachable(start):
        seen, todo = set(), [start]
        while todo:
            for nxt in graph.get(todo.pop(), ()):
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    mine = [m for m in graph if m == layer or m.startswith(layer + ".")]
    circles = sorted(f"{a} <-> {b}" for a in mine for b in graph[a] if b != a and a in reachable(b))
    assert not circles, "imports that lead back to the importer:\n" + "\n".join(circles)
