"""The floors stay honest (docs/conventions.md, ../shared/docs/architecture.md): every import in the code,
module-level or inside functions, is checked against the contract."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


@functools.lru_cache(maxsize=1)
def imports_by_module() -> dict[str, frozenset[str]]:
    """{module: every absolute module name it imports} for tracker/ and sot_apps/."""
    out: dict[str, set[str]] = {}
    for root in ("tracker", "sot_apps"):
        for path in sorted((REPO / root).rglob("*.py")):
            name = _module_name(path)
            package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
            found: set[str] = set()
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    found.update(alias.name for alias in node.names)
                elif isinstance(node, ast.ImportFrom):
                    if node.level:
                        base = package.split(".")
                        base = base[:len(base) - (node.level - 1)]
                        target = ".".join(base + ([node.module] if node.module else []))
                    else:
                        target = node.module or ""
                    found.add(target)
                    found.update(f"{target}.{alias.name}" for alias in node.names)
            out[name] = frozenset(found)
    return out


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def violations(rule: str, importer: str, imported: str,
               graph: dict[str, frozenset[str]] | None = None) -> list[str]:
    graph = imports_by_module() if graph is None else graph
    return sorted(f"{m} imports {i} ({rule})" for m, found in graph.items() if _in(m, importer)
                  for i in found if _in(i, imported))


def test_tracker_imports_nothing_from_sot_apps():
    assert violations("tracker is the core", "tracker", "sot_apps") == []


APPS = ("sot_apps.flow", "sot_apps.motion_export", "sot_apps.lidar_sim", "sot_apps.synth", "sot_apps.benchmark",
        "sot_apps.detection")
FLOOR = ("sot_apps.objects", "sot_apps.raycast", "sot_apps.sensor", "sot_apps.io")


def registered_apps() -> tuple[str, ...]:
    """The built-in apps of the registry (sot_apps.apps.bank, ...), from pyproject.toml's entry points."""
    import tomllib

    doc = tomllib.loads((REPO / "pyproject.toml").read_text())
    return tuple(sorted({v.split(":")[0] for v in doc["project"]["entry-points"]["sot_apps.apps"].values()}))


def test_evaluation_runs_no_app():
    """Evaluation only scores results it is given: it never imports an app (bench and the CLI run them)."""
    apps = APPS + ("sot_apps.apps", "sot_apps.pipeline")
    assert [v for a in apps for v in violations("evaluation only scores", "sot_apps.evaluation", a)] == []
    # the measurements that run apps and score them live in bench (the checker sees them there)
    assert "sot_apps.flow.annotate" in imports_by_module()["sot_apps.bench.flow_quality"]


TRACKER_RUNNERS = ("tracker.track", "tracker.Tracker", "tracker.sotracker", "tracker.refine_offline",
                   "tracker.refine_fixed_lag", "tracker.FixedLagSmoother", "tracker.offline", "tracker.fixed_lag",
                   "sot_apps.tracking")


def test_evaluation_runs_no_tracker():
    """Evaluation scores the results it is given: running the tracker (online, fixed lag, offline) belongs to bench
    and the CLI (sot_apps.bench.sequence_eval, benchmark_eval, reference)."""
    assert [v for r in TRACKER_RUNNERS for v in violations("evaluation only scores", "sot_apps.evaluation", r)] == []
    # the runners import the scorers: the checker sees both sides
    assert "sot_apps.tracking.track_objects" in imports_by_module()["sot_apps.bench.sequence_eval"]
    assert "sot_apps.evaluation.tracker" in imports_by_module()["sot_apps.bench.sequence_eval"]


def test_the_contract_rules_catch_a_violation():
    """Both evaluation rules fail on a module that breaks them (a rule that cannot fail proves nothing)."""
    bad = {"sot_apps.evaluation.bad": frozenset({"tracker.track", "sot_apps.flow.dense"}),
           "sot_apps.flow.bad": frozenset({"sot_apps.evaluation.tracker"})}
    assert violations("x", "sot_apps.evaluation", "tracker.track", bad) == [
        "sot_apps.evaluation.bad imports tracker.track (x)"]
    assert violations("x", "sot_apps.evaluation", "sot_apps.flow", bad) == [
        "sot_apps.evaluation.bad imports sot_apps.flow.dense (x)"]
    assert violations("x", "sot_apps.flow", "sot_apps.evaluation", bad) == [
        "sot_apps.flow.bad imports sot_apps.evaluation.tracker (x)"]
    assert violations("x", "sot_apps.evaluation", "tracker.track") == []   # the real tree keeps the rule


def test_apps_import_no_evaluation():
    assert len(registered_apps()) >= 5 and all(_in(a, "sot_apps.apps") for a in registered_apps())
    apps = APPS + ("sot_apps.apps",)
    assert [v for a in apps for v in violations("apps import no evaluation", a, "sot_apps.evaluation")] == []
    # the pipeline scores the motion export (the motion app does not): the checker sees that function-level import
    assert "sot_apps.evaluation.motion" in imports_by_module()["sot_apps.pipeline.stages"]


def test_registered_apps_are_siblings():
    """A built-in app reaches its library through the floor and its own package, never through another app's
    registration module, the pipeline, bench or the CLI (a third-party app could not either)."""
    mine = registered_apps()
    above = ("sot_apps.pipeline", "sot_apps.bench", "sot_apps.cli", "sot_apps.report")
    bad = [v for a in mine for b in mine + above if a != b for v in violations("apps are siblings", a, b)]
    assert bad == []


def test_apps_never_import_each_other():
    """(e.g. the benchmark simulates sweeps with the floor's sensor model, never through lidar_sim)"""
    bad = [v for a in APPS for b in APPS if a != b for v in violations("apps are siblings", a, b)]
    assert bad == []


def test_realism_evaluation_simulates_with_the_floor():
    """``bench realism`` simulates with sot_apps.sensor, not through the simulate-lidar app."""
    assert [v for a in ("sot_apps.lidar_sim", "sot_apps.benchmark")
            for v in violations("evaluation uses the floor", "sot_apps.evaluation", a)] == []


def test_the_floor_imports_no_app():
    floor = FLOOR
    apps = APPS + ("sot_apps.apps", "sot_apps.pipeline", "sot_apps.evaluation", "sot_apps.bench", "sot_apps.report",
                   "sot_apps.cli")
    assert [v for f in floor for a in apps for v in violations("the floor is below the apps", f, a)] == []


def test_report_never_imports_bench():
    assert violations("report renders what it is given", "sot_apps.report", "sot_apps.bench") == []


def test_evaluation_never_imports_bench_or_report():
    assert violations("evaluation is pure", "sot_apps.evaluation", "sot_apps.bench") == []
    assert violations("evaluation is pure", "sot_apps.evaluation", "sot_apps.report") == []


def test_only_the_cli_imports_the_cli():
    graph = imports_by_module()
    bad = sorted(f"{m} imports {i}" for m, found in graph.items() if not _in(m, "sot_apps.cli")
                 for i in found if _in(i, "sot_apps.cli"))
    assert bad == []


def test_no_private_names_across_packages():
    """``from other_package import _private`` is a hidden coupling (e.g. bench reaching into flow)."""
    bad = []
    for path in sorted((REPO / "sot_apps").rglob("*.py")):
        name = _module_name(path)
        top = ".".join(name.split(".")[:2])
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level >= 2 and node.module:
                target_top = "sot_apps." + node.module.split(".")[0]
                if target_top != top:
                    bad += [f"{name}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert bad == []


def test_the_contract_checker_sees_imports():
    """The checker itself: it must see function-level relative imports (a contract that sees nothing passes)."""
    graph = imports_by_module()
    assert "sot_apps.objects.selection" in graph["sot_apps.summary"]
    assert "sot_apps.evaluation.tracker" in graph["sot_apps.cli.eval"]        # inside run()
    assert "sot_apps.raycast" in graph["sot_apps.sensor.scan"]


def test_apps_import_the_tracker_through_its_package():
    """``tracker/__init__`` exports what the apps use; the apps import from it, not from its modules.
    (sot_apps.io is left to the reader branches merged on top.)"""
    graph = imports_by_module()
    bad = sorted(f"{m} imports {i}" for m, found in graph.items() if _in(m, "sot_apps") and not _in(m, "sot_apps.io")
                 for i in found if i.startswith("tracker.") and i.split(".")[1] not in __import__("tracker").__all__)
    assert bad == []


def test_report_runs_no_tracker_and_no_evaluation():
    """The report draws the records the pipeline saved (shape_growth.json, motion_eval.json)."""
    forbidden = ("tracker.Tracker", "tracker.track", "tracker.sotracker", "sot_apps.evaluation.motion.evaluate_motion",
                 "sot_apps.motion_export")
    assert [v for f in forbidden for v in violations("report renders what it is given", "sot_apps.report", f)] == []
